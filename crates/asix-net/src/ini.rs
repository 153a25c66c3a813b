//! A small, tolerant INI reader with Windows `GetPrivateProfileString` matching rules:
//! section and key names compare case-insensitively, a key may repeat, lines starting
//! with `;` or `#` are comments, and values are trimmed (no inline comments).

/// One `[section]` with its entries in file order.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Section {
    pub name: String,
    pub entries: Vec<(String, String)>,
}

/// A parsed INI text. Entries before the first section belong to a section named "".
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Ini {
    pub sections: Vec<Section>,
}

impl Ini {
    pub fn parse(text: &str) -> Ini {
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let mut sections = vec![Section::default()];
        for line in text.lines() {
            let line = line.trim();
            if line.is_empty() || line.starts_with(';') || line.starts_with('#') {
                continue;
            }
            if let Some(rest) = line.strip_prefix('[') {
                let name = rest.split(']').next().unwrap_or(rest).trim();
                sections.push(Section {
                    name: name.to_owned(),
                    entries: Vec::new(),
                });
                continue;
            }
            if let Some((k, v)) = line.split_once('=') {
                if let Some(cur) = sections.last_mut() {
                    cur.entries.push((k.trim().to_owned(), v.trim().to_owned()));
                }
            }
        }
        Ini { sections }
    }

    /// Every entry of every section called `section` (sections may repeat), in file order.
    pub fn entries<'a>(
        &'a self,
        section: &'a str,
    ) -> impl Iterator<Item = (&'a str, &'a str)> + 'a {
        self.sections
            .iter()
            .filter(move |s| s.name.eq_ignore_ascii_case(section))
            .flat_map(|s| s.entries.iter().map(|(k, v)| (k.as_str(), v.as_str())))
    }

    /// Every value of `key` in `section`.
    pub fn get_all<'a>(
        &'a self,
        section: &'a str,
        key: &'a str,
    ) -> impl Iterator<Item = &'a str> + 'a {
        self.entries(section)
            .filter(move |(k, _)| k.eq_ignore_ascii_case(key))
            .map(|(_, v)| v)
    }

    /// The first value of `key` in `section`, as `GetPrivateProfileString` returns it.
    pub fn get(&self, section: &str, key: &str) -> Option<&str> {
        self.entries_in(section)
            .find(|(k, _)| k.eq_ignore_ascii_case(key))
            .map(|(_, v)| v)
    }

    fn entries_in(&self, section: &str) -> impl Iterator<Item = (&str, &str)> {
        let section = section.to_owned();
        self.sections
            .iter()
            .filter(move |s| s.name.eq_ignore_ascii_case(&section))
            .flat_map(|s| s.entries.iter().map(|(k, v)| (k.as_str(), v.as_str())))
    }
}

/// Splits a comma-separated list, trimming items and dropping empty ones.
pub fn split_list(s: &str) -> Vec<String> {
    s.split(',')
        .map(str::trim)
        .filter(|x| !x.is_empty())
        .map(str::to_owned)
        .collect()
}

/// Parses an asix / AsixConnect boolean: `tak`/`true`/`1`/`yes` or `nie`/`false`/`0`/`no`.
pub fn parse_bool(s: &str) -> Option<bool> {
    match s.trim().to_ascii_lowercase().as_str() {
        "tak" | "true" | "1" | "yes" => Some(true),
        "nie" | "false" | "0" | "no" => Some(false),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sections_and_keys_are_case_insensitive_and_keys_repeat() {
        let ini = Ini::parse(
            "\u{feff}top=1\n[ASMEN]\n; comment\nZEZWOLENIE_ZAPISU = K1, KE2\nzezwolenie_zapisu=K2,X\n[asmen]\nZEZWOLENIE_ZAPISU = K3 , Y \n",
        );
        assert_eq!(ini.get("", "TOP"), Some("1"));
        let all: Vec<_> = ini.get_all("Asmen", "Zezwolenie_Zapisu").collect();
        assert_eq!(all, ["K1, KE2", "K2,X", "K3 , Y"]);
        assert_eq!(split_list(all[2]), ["K3", "Y"]);
        assert_eq!(ini.get("NOPE", "x"), None);
    }
}
