//! The languages the server speaks (IOPCCommon locale IDs, OPC UA LocaleIds): Polish and
//! English (US).
//!
//! AsixConnect 4 offered Polish (0x0415) and English US (0x0409); every other English
//! variant is accepted and answered in US English. The neutral/default locale IDs map to
//! the server's default language, which the caller passes in (Polish on Polish Windows,
//! English elsewhere: see [`Lang::default_for_system`]).

/// A language of error texts, property descriptions and browse texts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Lang {
    Polish,
    English,
}

/// LOCALE_NEUTRAL.
pub const LOCALE_NEUTRAL: u32 = 0x0000;
/// LOCALE_INVARIANT (answered in English).
pub const LOCALE_INVARIANT: u32 = 0x007F;
/// LOCALE_USER_DEFAULT.
pub const LOCALE_USER_DEFAULT: u32 = 0x0400;
/// LOCALE_SYSTEM_DEFAULT.
pub const LOCALE_SYSTEM_DEFAULT: u32 = 0x0800;
/// Polish (Poland).
pub const LCID_POLISH: u32 = 0x0415;
/// English (United States).
pub const LCID_ENGLISH_US: u32 = 0x0409;

const LANG_ENGLISH: u32 = 0x09;
const LANG_POLISH: u32 = 0x15;

impl Lang {
    /// Every language, in the order `available_lcids` lists them.
    pub const ALL: [Lang; 2] = [Lang::Polish, Lang::English];

    /// The language for a client's LCID, or `None` when the server does not support it
    /// (IOPCCommon::SetLocaleID then fails with E_INVALIDARG).
    ///
    /// - primary language 0x15 (0x0415) is Polish;
    /// - primary language 0x09 (0x0409, 0x0809, 0x0C09, ...) is English;
    /// - LOCALE_NEUTRAL, LOCALE_USER_DEFAULT and LOCALE_SYSTEM_DEFAULT are `server_default`;
    /// - LOCALE_INVARIANT is English.
    ///
    /// The sort ID (bits 16-19) is ignored.
    pub const fn from_lcid(lcid: u32, server_default: Lang) -> Option<Lang> {
        let lang_id = lcid & 0xFFFF;
        match lang_id {
            LOCALE_NEUTRAL | LOCALE_USER_DEFAULT | LOCALE_SYSTEM_DEFAULT => {
                return Some(server_default)
            }
            LOCALE_INVARIANT => return Some(Lang::English),
            _ => {}
        }
        match lang_id & 0x03FF {
            LANG_POLISH => Some(Lang::Polish),
            LANG_ENGLISH => Some(Lang::English),
            _ => None,
        }
    }

    /// The canonical LCID of this language (0x0415 or 0x0409).
    pub const fn lcid(self) -> u32 {
        match self {
            Lang::Polish => LCID_POLISH,
            Lang::English => LCID_ENGLISH_US,
        }
    }

    /// The LCIDs IOPCCommon::QueryAvailableLocaleIDs reports.
    pub const fn available_lcids() -> &'static [u32] {
        &[LCID_POLISH, LCID_ENGLISH_US]
    }

    /// The language for an OPC UA session's LocaleIds (ActivateSession: RFC 3066 tags in
    /// the client's order of preference): the first that names Polish (`pl`, `pl-PL`) or
    /// English (`en`, `en-US`, `en-GB`, ...) by its primary subtag, case-insensitive;
    /// `server_default` when none does (no LocaleIds, or only other languages), as OPC UA
    /// Part 4 says of a server that supports none of the session's locales.
    pub fn from_locale_ids<S: AsRef<str>>(
        locale_ids: impl IntoIterator<Item = S>,
        server_default: Lang,
    ) -> Lang {
        locale_ids
            .into_iter()
            .find_map(|id| {
                let id = id.as_ref().trim();
                let primary = id.split(['-', '_']).next().unwrap_or(id);
                if primary.eq_ignore_ascii_case("pl") {
                    Some(Lang::Polish)
                } else if primary.eq_ignore_ascii_case("en") {
                    Some(Lang::English)
                } else {
                    None
                }
            })
            .unwrap_or(server_default)
    }

    /// The locale of texts in this language (an OPC UA LocalizedText's locale): `pl` or
    /// `en`.
    pub const fn locale_id(self) -> &'static str {
        match self {
            Lang::Polish => "pl",
            Lang::English => "en",
        }
    }

    /// The server's default language for the system (or user) default LCID of the
    /// machine: Polish on Polish Windows, English everywhere else.
    pub const fn default_for_system(system_lcid: u32) -> Lang {
        if system_lcid & 0x03FF == LANG_POLISH {
            Lang::Polish
        } else {
            Lang::English
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lcid_table_maps_to_languages() {
        // (lcid, server default, expected)
        let table: &[(u32, Lang, Option<Lang>)] = &[
            (0x0415, Lang::English, Some(Lang::Polish)),
            (0x0015, Lang::English, Some(Lang::Polish)),
            (0x0409, Lang::Polish, Some(Lang::English)),
            (0x0809, Lang::Polish, Some(Lang::English)), // en-GB
            (0x0C09, Lang::Polish, Some(Lang::English)), // en-AU
            (0x1009, Lang::Polish, Some(Lang::English)), // en-CA
            (0x4009, Lang::Polish, Some(Lang::English)), // en-IN
            (0x0009, Lang::Polish, Some(Lang::English)),
            (0x0001_0409, Lang::Polish, Some(Lang::English)), // sort ID ignored
            (LOCALE_NEUTRAL, Lang::Polish, Some(Lang::Polish)),
            (LOCALE_NEUTRAL, Lang::English, Some(Lang::English)),
            (LOCALE_USER_DEFAULT, Lang::Polish, Some(Lang::Polish)),
            (LOCALE_SYSTEM_DEFAULT, Lang::English, Some(Lang::English)),
            (LOCALE_SYSTEM_DEFAULT, Lang::Polish, Some(Lang::Polish)),
            (LOCALE_INVARIANT, Lang::Polish, Some(Lang::English)),
            (0x0407, Lang::Polish, None),  // de-DE
            (0x0419, Lang::English, None), // ru-RU
            (0x0405, Lang::English, None), // cs-CZ
        ];
        for &(lcid, default, expected) in table {
            assert_eq!(
                Lang::from_lcid(lcid, default),
                expected,
                "lcid 0x{lcid:04X}"
            );
        }
    }

    #[test]
    fn every_available_lcid_round_trips() {
        for &lcid in Lang::available_lcids() {
            let lang = Lang::from_lcid(lcid, Lang::English).unwrap();
            assert_eq!(lang.lcid(), lcid);
        }
        for lang in Lang::ALL {
            assert_eq!(Lang::from_lcid(lang.lcid(), Lang::English), Some(lang));
        }
    }

    #[test]
    fn ua_locale_ids_pick_the_first_supported_language() {
        // (LocaleIds, server default, expected)
        let table: &[(&[&str], Lang, Lang)] = &[
            (&["pl"], Lang::English, Lang::Polish),
            (&["pl-PL"], Lang::English, Lang::Polish),
            (&["PL-pl"], Lang::English, Lang::Polish),
            (&["pl_PL"], Lang::English, Lang::Polish),
            (&["en-US"], Lang::Polish, Lang::English),
            (&["en"], Lang::Polish, Lang::English),
            (&["en-GB"], Lang::Polish, Lang::English),
            (&["de", "pl"], Lang::English, Lang::Polish),
            (&["de-DE", "en-US", "pl"], Lang::Polish, Lang::English),
            (&["pl", "en"], Lang::English, Lang::Polish),
            (&["de"], Lang::English, Lang::English),
            (&["de"], Lang::Polish, Lang::Polish),
            (&[], Lang::English, Lang::English),
            (&[], Lang::Polish, Lang::Polish),
            (&[""], Lang::Polish, Lang::Polish),
            // Only the primary subtag counts: `plx` and `eng` name neither.
            (&["plx", "eng"], Lang::Polish, Lang::Polish),
            (&["plx", "eng"], Lang::English, Lang::English),
        ];
        for &(ids, default, expected) in table {
            assert_eq!(
                Lang::from_locale_ids(ids, default),
                expected,
                "{ids:?}, default {default:?}"
            );
        }
    }

    #[test]
    fn a_chosen_language_names_itself_as_a_locale_the_picker_takes_back() {
        for lang in Lang::ALL {
            let other = match lang {
                Lang::Polish => Lang::English,
                Lang::English => Lang::Polish,
            };
            assert_eq!(Lang::from_locale_ids([lang.locale_id()], other), lang);
        }
        assert_eq!(Lang::Polish.locale_id(), "pl");
        assert_eq!(Lang::English.locale_id(), "en");
    }

    #[test]
    fn server_default_is_polish_only_on_polish_systems() {
        assert_eq!(Lang::default_for_system(0x0415), Lang::Polish);
        assert_eq!(Lang::default_for_system(0x0409), Lang::English);
        assert_eq!(Lang::default_for_system(0x0407), Lang::English);
    }
}
