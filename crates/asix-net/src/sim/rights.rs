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
//! line may name several clients after the channel (`= KANAL1, KE2, KE3`). The file is read
//! as the asix side writes it ([`parse_ini_tolerant`]).

use std::collections::{HashMap, HashSet};

use asix_model::ini::{parse_ini_tolerant, split_list};
use asix_model::text::parse_bool;
use asix_model::Warning;

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
    /// Reads the rights from the bytes of an asix application ini; `file` names it in the
    /// warnings about lines that could not be read (which are skipped).
    pub fn from_app_ini(bytes: &[u8], file: &str) -> (WriteRights, Vec<Warning>) {
        let (ini, warnings) = parse_ini_tolerant(bytes, file);
        let mut r = WriteRights::default();
        for e in ini.section("ASMEN").iter().flat_map(|s| &s.entries) {
            let list = split_list(&e.value);
            if e.key.eq_ignore_ascii_case(PERMIT_KEY) {
                if let Some((channel, clients)) = list.split_first() {
                    for c in clients {
                        r.permits
                            .insert((channel.to_ascii_uppercase(), c.to_ascii_uppercase()));
                    }
                }
            } else if let Some(driver) = list.first() {
                // Any other [ASMEN] line is read as a channel definition: `<channel> = <driver>, ...`.
                r.drivers.insert(e.key.to_ascii_uppercase(), driver.clone());
            }
        }
        for s in &ini.sections {
            if let Some(e) = s.get("ZAPIS_CZASU_I_STATUSU") {
                if parse_bool(&e.value) == Some(true) {
                    r.time_and_status.insert(s.name.to_ascii_uppercase());
                }
            }
        }
        (r, warnings)
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

    fn rights(text: &str) -> WriteRights {
        let (r, warnings) = WriteRights::from_app_ini(text.as_bytes(), "app.ini");
        assert!(warnings.is_empty(), "{warnings:?}");
        r
    }

    #[test]
    fn manual_example_and_many_entries() {
        let r = rights(INI);
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
        let r = rights(INI);
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

    #[test]
    fn windows_1250_file_and_unreadable_lines() {
        // Channel `PIEC_Ł` in Windows-1250; an unreadable line and an unterminated header
        // are skipped with warnings, and the flag under that header does not count.
        let bytes = b"[ASMEN]\nPIEC_\xA3 = NONE\n???\nZEZWOLENIE_ZAPISU = PIEC_\xA3, KE2\n\
            [PIEC_\xA3\nZAPIS_CZASU_I_STATUSU = TAK\n";
        let (r, warnings) = WriteRights::from_app_ini(bytes, "app.ini");
        assert_eq!(r.driver("PIEC_Ł"), Some("NONE"));
        assert_eq!(r.check_write("PIEC_Ł", "KE2", false), Ok(()));
        assert_eq!(
            r.check_write_extended("PIEC_Ł", "KE2", false),
            Err(Denied::NoExtendedWrite)
        );
        let lines: Vec<usize> = warnings.iter().map(|w| w.line).collect();
        assert_eq!(lines, [3, 5, 6], "{warnings:?}");
    }
}
