//! Files that hold secrets (private keys, the OPC UA users file) are readable only by the
//! account the server runs as (and administrators): the decision on a Unix file mode, pure.
//!
//! A key or users file that its group or others may read is reported, not refused: the
//! server WARNs when it loads one and `opcdiag doctor` lists it, with the fix (`chmod
//! 600`). Refusing (ssh's way) would stop a plant's server over a file it has served from
//! for years; the files ServerCTOPC and asix-sim write are 0600 from the start.

/// The mode the files of secrets are written with: read and write for the owner only.
pub const PRIVATE_MODE: u32 = 0o600;

/// What is wrong with a secret file of Unix mode `mode` (`st_mode`, any file type bits):
/// `None` when neither its group nor others have any right on it, else one sentence with
/// the fix.
pub fn mode_finding(mode: u32) -> Option<String> {
    let group = mode & 0o070;
    let other = mode & 0o007;
    let who = match (group != 0, other != 0) {
        (false, false) => return None,
        (true, false) => "its group",
        (false, true) => "others",
        (true, true) => "its group and others",
    };
    Some(format!(
        "mode {:04o}: {who} may {} it (chmod 600)",
        mode & 0o7777,
        if (group | other) & 0o044 != 0 {
            "read"
        } else {
            "write or run"
        }
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_an_owner_only_mode_passes() {
        let table: &[(u32, Option<&str>)] = &[
            (0o600, None),
            (0o400, None),
            (0o100600, None),
            (0o700, None),
            (0o640, Some("mode 0640: its group may read it (chmod 600)")),
            (0o604, Some("mode 0604: others may read it (chmod 600)")),
            (
                0o100644,
                Some("mode 0644: its group and others may read it (chmod 600)"),
            ),
            (
                0o620,
                Some("mode 0620: its group may write or run it (chmod 600)"),
            ),
            (
                0o666,
                Some("mode 0666: its group and others may read it (chmod 600)"),
            ),
        ];
        for (mode, want) in table {
            assert_eq!(mode_finding(*mode).as_deref(), *want, "{mode:o}");
        }
        assert_eq!(mode_finding(PRIVATE_MODE), None);
    }
}
