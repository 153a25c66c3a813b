//! Write rights from an asix application ini (manual §6.3):
//!
//! ```ini
//! [ASMEN]
//! KANAL1 = NONE                      ; channel KANAL1 on driver NONE
//! ZEZWOLENIE_ZAPISU = KANAL1, KE2    ; client KE2 may write to KANAL1
//! [KANAL1]
//! ZAPIS_CZASU_I_STATUSU = TAK        ; extended (value+quality+time) writes allowed
//! ```
//!
//! Names compare case-insensitively (INI rules). `ZEZWOLENIE_ZAPISU` may repeat, and one
//! line may name several clients after the channel (`= KANAL1, KE2, KE3`).

use std::collections::{HashMap, HashSet};

use crate::ini::{parse_bool, split_list, Ini};

/// Why a write is refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Denied {
    /// No `ZEZWOLENIE_ZAPISU` entry for this channel and client (and the client is remote).
    NoPermission,
    /// Extended write on a channel not on driver NONE or without `ZAPIS_CZASU_I_STATUSU = TAK`.
    NoExtendedWrite,
}

/// The write rights of one asix application.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct WriteRights {
    /// (channel, client), upper-cased.
    permits: HashSet<(String, String)>,
    /// channel (upper-cased) -> driver name as written.
    drivers: HashMap<String, String>,
    /// Channels (upper-cased) with `ZAPIS_CZASU_I_STATUSU = TAK`.
    time_and_status: HashSet<String>,
}

const PERMIT_KEY: &str = "ZEZWOLENIE_ZAPISU";

impl WriteRights {
    pub fn from_app_ini(text: &str) -> WriteRights {
        let ini = Ini::parse(text);
        let mut r = WriteRights::default();
        for (k, v) in ini.entries("ASMEN") {
            let list = split_list(v);
            if k.eq_ignore_ascii_case(PERMIT_KEY) {
                if let Some((channel, clients)) = list.split_first() {
                    for c in clients {
                        r.permits
                            .insert((channel.to_ascii_uppercase(), c.to_ascii_uppercase()));
                    }
                }
            } else if let Some(driver) = list.first() {
                // Any other [ASMEN] line is read as a channel definition: `<channel> = <driver>, ...`.
                r.drivers.insert(k.to_ascii_uppercase(), driver.clone());
            }
        }
        for s in &ini.sections {
            if let Some(v) = ini.get(&s.name, "ZAPIS_CZASU_I_STATUSU") {
                if parse_bool(v) == Some(true) {
                    r.time_and_status.insert(s.name.to_ascii_uppercase());
                }
            }
        }
        r
    }

    /// The driver of a channel, if the ini defines it.
    pub fn driver(&self, channel: &str) -> Option<&str> {
        self.drivers
            .get(&channel.to_ascii_uppercase())
            .map(String::as_str)
    }

    /// Does an entry grant `client` writes to `channel`?
    pub fn permits(&self, channel: &str, client: &str) -> bool {
        self.permits
            .contains(&(channel.to_ascii_uppercase(), client.to_ascii_uppercase()))
    }

    /// A simple write: local clients always; remote ones need the permission entry.
    pub fn check_write(&self, channel: &str, client: &str, local: bool) -> Result<(), Denied> {
        if local || self.permits(channel, client) {
            Ok(())
        } else {
            Err(Denied::NoPermission)
        }
    }

    /// An extended write: as a simple write, and the channel must be on driver `NONE` with
    /// `ZAPIS_CZASU_I_STATUSU = TAK` in its section. (*Inference: local clients are exempt from
    /// the permission entry, as for simple writes, but not from the channel conditions.*)
    pub fn check_write_extended(
        &self,
        channel: &str,
        client: &str,
        local: bool,
    ) -> Result<(), Denied> {
        self.check_write(channel, client, local)?;
        let none = self
            .driver(channel)
            .is_some_and(|d| d.eq_ignore_ascii_case("NONE"));
        if none && self.time_and_status.contains(&channel.to_ascii_uppercase()) {
            Ok(())
        } else {
            Err(Denied::NoExtendedWrite)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const INI: &str = "[ASMEN]\nKANAL1=NONE\nKANAL2 = MODBUS, COM1\nKANAL3=NONE\n\
        ZEZWOLENIE_ZAPISU = KANAL1, KE2\nZEZWOLENIE_ZAPISU = KANAL2, KE2, OP3.\n\
        ZEZWOLENIE_ZAPISU = KANAL3, KE2\n[KANAL1]\nZAPIS_CZASU_I_STATUSU = TAK\n\
        [KANAL2]\nZAPIS_CZASU_I_STATUSU = TAK\n[KANAL3]\nZAPIS_CZASU_I_STATUSU = NIE\n";

    #[test]
    fn manual_example_and_many_entries() {
        let r = WriteRights::from_app_ini(INI);
        assert_eq!(r.check_write("KANAL1", "KE2", false), Ok(()));
        assert_eq!(r.check_write("kanal1", "ke2", false), Ok(()));
        assert_eq!(
            r.check_write("KANAL1", "OP3.", false),
            Err(Denied::NoPermission)
        );
        assert_eq!(r.check_write("KANAL2", "OP3.", false), Ok(()));
        assert_eq!(r.check_write("KANAL1", "OP3.", true), Ok(()));
        assert_eq!(r.driver("KANAL2"), Some("MODBUS"));
    }

    #[test]
    fn extended_write_needs_permission_driver_none_and_the_section_flag() {
        let r = WriteRights::from_app_ini(INI);
        assert_eq!(r.check_write_extended("KANAL1", "KE2", false), Ok(()));
        assert_eq!(
            r.check_write_extended("KANAL1", "X.", false),
            Err(Denied::NoPermission)
        );
        assert_eq!(
            r.check_write_extended("KANAL2", "KE2", false),
            Err(Denied::NoExtendedWrite)
        );
        assert_eq!(
            r.check_write_extended("KANAL3", "KE2", false),
            Err(Denied::NoExtendedWrite)
        );
        assert_eq!(r.check_write_extended("KANAL1", "X.", true), Ok(()));
        assert_eq!(
            WriteRights::default().check_write_extended("KANAL1", "X.", true),
            Err(Denied::NoExtendedWrite)
        );
    }
}
