//! `MatchPattern`: the browse name filter of OPC DA, with the semantics of the Visual Basic
//! `LIKE` operator (OPC DA 2.05a appendix, OPC Foundation `OpcMatchPattern`).
//!
//! | in the pattern | matches in the string |
//! |---|---|
//! | `?` | any single character |
//! | `*` | zero or more characters |
//! | `#` | any single digit `0`–`9` |
//! | `[charlist]` | any single character in the list |
//! | `[!charlist]` | any single character not in the list |
//! | any other character | itself |
//!
//! Inside brackets: `a-z` is a range (bounds in ascending order); a hyphen first (after
//! the `!`, if any) or last matches itself; `[`, `*`, `?`, `#` match themselves, so
//! `[[]`, `[*]`, `[?]`, `[#]` are the escapes. `]` cannot be in a list; outside brackets
//! it, like `!`, matches itself.
//!
//! Choices where the sources differ or are silent (documented in `browse/mod.rs` too):
//! - `[]` is a zero-length string, as the VB documentation says (the OPC Foundation C code
//!   fails on it instead). `[!]` matches any single character (as that C code does).
//! - A **malformed pattern** — an unclosed `[`, or a reversed range such as `[Z-A]` — is an
//!   error for [`Pattern::new`] (VB raises run-time error 93) and matches **nothing** in
//!   [`match_pattern`]. The browse methods report it as `OPC_E_INVALIDFILTER`.
//! - **Case**: a parameter. The OPC Foundation `OpcMatchPattern(szString, szPattern,
//!   bCaseSensitive = false)` is case-*insensitive* by default and its sample server browses
//!   with that default; VB's default (`Option Compare Binary`) is case-sensitive. Case
//!   folding here is Unicode simple case mapping, character by character (no locale
//!   collation, unlike `Option Compare Text`).
//! - `#` matches ASCII digits only.
//!
//! Matching runs in O(|pattern| · |string|) worst case and usually linear (two pointers with
//! back-off to the last `*`; no exponential backtracking), since every token but `*`
//! consumes exactly one character.

use thiserror::Error;

/// Whether letters must agree in case.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum MatchCase {
    /// `A` matches only `A` (VB `Option Compare Binary`).
    Sensitive,
    /// `A` matches `A` and `a` (the OPC Foundation `OpcMatchPattern` default).
    #[default]
    Insensitive,
}

/// Why a pattern is malformed.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum PatternError {
    /// A `[` without its `]`; the position is a character index in the pattern.
    #[error("unclosed '[' at character {0}")]
    UnclosedBracket(usize),
    /// A range whose bounds are in descending order, e.g. `[Z-A]`.
    #[error("range '{low}-{high}' is in descending order")]
    ReversedRange { low: char, high: char },
}

#[derive(Debug, Clone, PartialEq, Eq)]
enum Token {
    Literal(char),
    AnyChar,
    Digit,
    /// Inclusive ranges; a single character `c` is `(c, c)`.
    Set {
        negated: bool,
        ranges: Box<[(char, char)]>,
    },
    Star,
}

/// A compiled pattern: compile once, match many names.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Pattern {
    tokens: Vec<Token>,
    case: MatchCase,
}

impl Pattern {
    /// Compiles `pattern`; see the module documentation for the syntax.
    pub fn new(pattern: &str, case: MatchCase) -> Result<Pattern, PatternError> {
        let p: Vec<char> = pattern.chars().collect();
        let mut tokens = Vec::new();
        let mut k = 0;
        while k < p.len() {
            let c = p[k];
            k += 1;
            match c {
                '*' => {
                    // `**` is `*`: keeping one keeps the matcher's back-off simple.
                    if tokens.last() != Some(&Token::Star) {
                        tokens.push(Token::Star);
                    }
                }
                '?' => tokens.push(Token::AnyChar),
                '#' => tokens.push(Token::Digit),
                '[' => {
                    let open = k - 1;
                    let negated = p.get(k) == Some(&'!');
                    if negated {
                        k += 1;
                    }
                    let mut ranges = Vec::new();
                    loop {
                        let Some(&first) = p.get(k) else {
                            return Err(PatternError::UnclosedBracket(open));
                        };
                        if first == ']' {
                            k += 1;
                            break;
                        }
                        // `x-y` is a range unless the hyphen is last in the list.
                        if p.get(k + 1) == Some(&'-')
                            && matches!(p.get(k + 2), Some(&h) if h != ']')
                        {
                            let high = p[k + 2];
                            if high < first {
                                return Err(PatternError::ReversedRange { low: first, high });
                            }
                            ranges.push((first, high));
                            k += 3;
                        } else {
                            ranges.push((first, first));
                            k += 1;
                        }
                    }
                    if negated || !ranges.is_empty() {
                        tokens.push(Token::Set {
                            negated,
                            ranges: ranges.into_boxed_slice(),
                        });
                    }
                    // `[]` is a zero-length string: no token.
                }
                other => tokens.push(Token::Literal(other)),
            }
        }
        Ok(Pattern { tokens, case })
    }

    /// The case rule this pattern was compiled with.
    pub fn case(&self) -> MatchCase {
        self.case
    }

    /// True when the pattern is `*` (or `**`, `*[]`, ...): it matches every string.
    pub fn matches_everything(&self) -> bool {
        self.tokens.iter().all(|t| *t == Token::Star) && !self.tokens.is_empty()
    }

    /// Whether `s` matches the whole pattern.
    pub fn matches(&self, s: &str) -> bool {
        let t = &self.tokens;
        let s: Vec<char> = s.chars().collect();
        let (mut i, mut j) = (0usize, 0usize);
        // After a `*`: the token index following it and the string index it resumes from.
        let mut back_off: Option<(usize, usize)> = None;
        while i < s.len() {
            match t.get(j) {
                Some(Token::Star) => {
                    j += 1;
                    back_off = Some((j, i));
                    continue;
                }
                Some(tok) if self.one(tok, s[i]) => {
                    i += 1;
                    j += 1;
                    continue;
                }
                _ => {}
            }
            // Mismatch: let the last `*` swallow one more character, or fail.
            match back_off {
                Some((bj, bi)) => {
                    j = bj;
                    i = bi + 1;
                    back_off = Some((bj, bi + 1));
                }
                None => return false,
            }
        }
        t[j..].iter().all(|tok| *tok == Token::Star)
    }

    /// Whether the single-character token `tok` matches `c`.
    fn one(&self, tok: &Token, c: char) -> bool {
        match tok {
            Token::Literal(l) => match self.case {
                MatchCase::Sensitive => *l == c,
                MatchCase::Insensitive => *l == c || fold(*l) == fold(c),
            },
            Token::AnyChar => true,
            Token::Digit => c.is_ascii_digit(),
            Token::Set { negated, ranges } => {
                let hit = match self.case {
                    MatchCase::Sensitive => in_ranges(ranges, c),
                    MatchCase::Insensitive => {
                        in_ranges(ranges, c)
                            || in_ranges(ranges, upper(c))
                            || in_ranges(ranges, lower(c))
                    }
                };
                hit != *negated
            }
            Token::Star => false,
        }
    }
}

fn in_ranges(ranges: &[(char, char)], c: char) -> bool {
    ranges.iter().any(|&(lo, hi)| lo <= c && c <= hi)
}

/// Simple (one-to-one) uppercase mapping; characters whose uppercase is several characters
/// (e.g. `ß`) stay as they are.
fn upper(c: char) -> char {
    let mut u = c.to_uppercase();
    match (u.next(), u.next()) {
        (Some(one), None) => one,
        _ => c,
    }
}

fn lower(c: char) -> char {
    let mut l = c.to_lowercase();
    match (l.next(), l.next()) {
        (Some(one), None) => one,
        _ => c,
    }
}

fn fold(c: char) -> char {
    lower(upper(c))
}

/// `MatchPattern(string, pattern, case)`: true if `string` matches `pattern`.
/// A malformed pattern matches nothing (see the module documentation).
pub fn match_pattern(string: &str, pattern: &str, case: MatchCase) -> bool {
    Pattern::new(pattern, case).is_ok_and(|p| p.matches(string))
}

/// A pattern that matches exactly `s` (and, case-insensitively, its case variants):
/// `[`, `*`, `?` and `#` are wrapped in brackets, every other character stands for itself.
pub fn escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 2);
    for c in s.chars() {
        match c {
            '[' | '*' | '?' | '#' => {
                out.push('[');
                out.push(c);
                out.push(']');
            }
            _ => out.push(c),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn sensitive(s: &str, p: &str) -> bool {
        match_pattern(s, p, MatchCase::Sensitive)
    }

    /// The examples of the Visual Basic `Like` operator documentation (Option Compare Binary).
    #[test]
    fn vb_like_documentation_examples() {
        let table: &[(&str, &str, bool)] = &[
            ("aBBBa", "a*a", true),
            ("F", "[A-Z]", true),
            ("F", "[!A-Z]", false),
            ("a2a", "a#a", true),
            ("aM5b", "a[L-P]#[!c-e]", true),
            ("BAT123khg", "B?T*", true),
            ("CAT123khg", "B?T*", false),
            ("ab", "a*b", true),
            ("a*b", "a [*]b", false),
            ("axxxxxb", "a [*]b", false),
            ("a [xyz", "a [[]*", true),
        ];
        for &(s, p, want) in table {
            assert_eq!(sensitive(s, p), want, "{s:?} Like {p:?}");
        }
    }

    /// VB: `"a [xyz" Like "a [*"` raises error 93 (invalid pattern string).
    #[test]
    fn vb_like_invalid_pattern_unclosed_bracket_matches_nothing() {
        assert_eq!(
            Pattern::new("a [*", MatchCase::Sensitive),
            Err(PatternError::UnclosedBracket(2))
        );
        assert!(!sensitive("a [xyz", "a [*"));
        assert!(!sensitive("", "["));
        assert!(!sensitive("[", "["));
        assert!(!sensitive("a", "[!a"));
    }

    /// VB: ranges must be in ascending order; `[A-Z]` is valid, `[Z-A]` is not.
    #[test]
    fn vb_like_descending_range_is_invalid() {
        assert_eq!(
            Pattern::new("[Z-A]", MatchCase::Sensitive),
            Err(PatternError::ReversedRange {
                low: 'Z',
                high: 'A'
            })
        );
        assert!(!sensitive("M", "[Z-A]"));
        assert!(sensitive("M", "[A-Z]"));
        assert!(sensitive("A", "[A-A]"));
    }

    #[test]
    fn wildcards_table() {
        let table: &[(&str, &str, bool)] = &[
            // `?`: exactly one character
            ("a", "?", true),
            ("", "?", false),
            ("ab", "?", false),
            ("ab", "??", true),
            // `*`: zero or more
            ("", "*", true),
            ("anything", "*", true),
            ("abc", "a*", true),
            ("abc", "*c", true),
            ("abc", "*b*", true),
            ("abc", "*d*", false),
            ("aXbXc", "a*b*c", true),
            ("abcabd", "*abd", true),
            ("mississippi", "m*iss*ppi", true),
            ("mississippi", "m*iss*ppx", false),
            // `#`: one digit
            ("7", "#", true),
            ("x", "#", false),
            ("", "#", false),
            ("12", "#", false),
            ("A12", "A##", true),
            // empty pattern matches only the empty string
            ("", "", true),
            ("a", "", false),
            // specials outside brackets
            ("]", "]", true),
            ("a]", "a]", true),
            ("!", "!", true),
            ("a-b", "a-b", true),
        ];
        for &(s, p, want) in table {
            assert_eq!(sensitive(s, p), want, "{s:?} Like {p:?}");
        }
    }

    #[test]
    fn charlist_table() {
        let table: &[(&str, &str, bool)] = &[
            ("b", "[abc]", true),
            ("d", "[abc]", false),
            ("d", "[!abc]", true),
            ("b", "[!abc]", false),
            ("q", "[a-z]", true),
            ("Q", "[a-z]", false),
            ("5", "[0-9A-F]", true),
            ("E", "[0-9A-F]", true),
            ("G", "[0-9A-F]", false),
            // range bounds are inclusive
            ("a", "[a-z]", true),
            ("z", "[a-z]", true),
            ("`", "[a-z]", false),
            ("{", "[a-z]", false),
            ("0", "[0-9]", true),
            ("9", "[0-9]", true),
            ("z", "[!a-z]", false),
            ("{", "[!a-z]", true),
            // escapes
            ("[", "[[]", true),
            ("*", "[*]", true),
            ("x", "[*]", false),
            ("?", "[?]", true),
            ("x", "[?]", false),
            ("#", "[#]", true),
            ("1", "[#]", false),
            // hyphen first / last is literal
            ("-", "[-a]", true),
            ("a", "[-a]", true),
            ("-", "[a-]", true),
            ("-", "[!-a]", false),
            ("b", "[!-a]", true),
            ("b", "[a-]", false),
            // a range followed by a hyphen and a character: the hyphen is literal
            ("-", "[a-c-e]", true),
            ("d", "[a-c-e]", false),
            ("e", "[a-c-e]", true),
            // `[]` is a zero-length string; `[!]` any single character
            ("ab", "a[]b", true),
            ("", "[]", true),
            ("x", "[]", false),
            ("x", "[!]", true),
            ("", "[!]", false),
            // `]` right after `[]` is a literal outside brackets
            ("]", "[]]", true),
            // `!` not first in the list is a member
            ("!", "[a!]", true),
        ];
        for &(s, p, want) in table {
            assert_eq!(sensitive(s, p), want, "{s:?} Like {p:?}");
        }
    }

    #[test]
    fn case_insensitive_matching_folds_literals_and_sets() {
        let ci = |s: &str, p: &str| match_pattern(s, p, MatchCase::Insensitive);
        assert!(ci("f", "[A-Z]"));
        assert!(!sensitive("f", "[A-Z]"));
        assert!(ci("PUMP_01", "pump_##"));
        assert!(!sensitive("PUMP_01", "pump_##"));
        assert!(!ci("f", "[!A-Z]"));
        assert!(ci("Ł", "ł*"));
        assert!(ci("zażółć", "ZAŻÓŁĆ"));
        assert!(ci("ß", "ß"));
        assert!(!ci("x", "[A-W]"));
    }

    #[test]
    fn unicode_characters_are_single_characters() {
        assert!(sensitive("ą", "?"));
        assert!(sensitive("Łódź", "?ód?"));
        assert!(sensitive("ę", "[ąę]"));
        assert!(!sensitive("٣", "#"), "# is ASCII 0-9 only");
    }

    #[test]
    fn pathological_star_patterns_run_fast() {
        let s = "a".repeat(5000);
        let p = format!("{}b", "*a".repeat(2000));
        assert!(!sensitive(&s, &p));
        let p = format!("{}*", "*a".repeat(2000));
        assert!(sensitive(&s, &p));
    }

    #[test]
    fn matches_everything_only_for_star_patterns() {
        assert!(Pattern::new("*", MatchCase::Sensitive)
            .unwrap()
            .matches_everything());
        assert!(Pattern::new("**[]", MatchCase::Sensitive)
            .unwrap()
            .matches_everything());
        assert!(!Pattern::new("", MatchCase::Sensitive)
            .unwrap()
            .matches_everything());
        assert!(!Pattern::new("*a", MatchCase::Sensitive)
            .unwrap()
            .matches_everything());
    }

    /// Independent oracle: a plain recursive interpreter of the raw pattern text
    /// (exponential, for small inputs), case-sensitive, for well-formed patterns.
    fn oracle(s: &[char], p: &[char]) -> bool {
        match p.first() {
            None => s.is_empty(),
            Some('*') => (0..=s.len()).any(|k| oracle(&s[k..], &p[1..])),
            Some('?') => !s.is_empty() && oracle(&s[1..], &p[1..]),
            Some('#') => s.first().is_some_and(|c| c.is_ascii_digit()) && oracle(&s[1..], &p[1..]),
            Some('[') => {
                let close = 1 + p[1..].iter().position(|&c| c == ']').expect("well-formed");
                // `[!]`: the first `]` after `[!` closes it.
                let body = &p[1..close];
                let rest = &p[close + 1..];
                let (neg, list) = match body.first() {
                    Some('!') => (true, &body[1..]),
                    _ => (false, body),
                };
                if !neg && list.is_empty() {
                    return oracle(s, rest);
                }
                let Some(&c) = s.first() else { return false };
                let mut member = false;
                let mut i = 0;
                while i < list.len() {
                    if i + 2 < list.len() && list[i + 1] == '-' {
                        member |= list[i] <= c && c <= list[i + 2];
                        i += 3;
                    } else {
                        member |= list[i] == c;
                        i += 1;
                    }
                }
                member != neg && oracle(&s[1..], rest)
            }
            Some(&l) => s.first() == Some(&l) && oracle(&s[1..], &p[1..]),
        }
    }

    fn pattern_piece() -> impl Strategy<Value = String> {
        prop::sample::select(vec![
            "a", "b", "c", "1", "2", "-", "!", "]", "?", "*", "#", "[ab]", "[!a]", "[a-c]",
            "[!0-9]", "[[]", "[*]", "[?]", "[#]", "[]", "[!]", "[-a]", "[b-]",
        ])
        .prop_map(str::to_owned)
    }

    fn pattern_strategy() -> impl Strategy<Value = String> {
        prop::collection::vec(pattern_piece(), 0..7).prop_map(|v| v.concat())
    }

    fn subject_strategy() -> impl Strategy<Value = String> {
        prop::collection::vec(
            prop::sample::select(vec![
                'a', 'b', 'c', 'A', '1', '2', '-', '!', ']', '[', '*', '?', '#',
            ]),
            0..9,
        )
        .prop_map(|v| v.into_iter().collect())
    }

    /// A pattern piece and characters near what it matches (inside, on and beyond the
    /// bounds), so generated subjects often match or miss by one character.
    fn piece_with_subject() -> impl Strategy<Value = (String, String)> {
        let pieces: Vec<(&'static str, &'static [&'static str])> = vec![
            ("a", &["a", "b", "A"]),
            ("?", &["a", "-", ""]),
            ("*", &["", "a", "ab", "c1c"]),
            ("#", &["0", "9", "a", "/", ":"]),
            ("[a-c]", &["a", "b", "c", "d", "`"]),
            ("[!a-c]", &["a", "c", "d", "`", "1"]),
            ("[0-2x]", &["0", "2", "3", "x", "y"]),
            ("[-a]", &["-", "a", "b"]),
            ("[b-]", &["-", "b", "c"]),
            ("[[]", &["[", "]", "a"]),
            ("[*]", &["*", "a"]),
            ("[]", &["", "a"]),
            ("[!]", &["a", ""]),
            ("]", &["]", "["]),
        ];
        prop::sample::select(pieces).prop_flat_map(|(p, subjects)| {
            prop::sample::select(subjects.to_vec()).prop_map(move |s| (p.to_owned(), s.to_owned()))
        })
    }

    proptest! {
        #[test]
        fn agrees_with_oracle_on_near_matching_subjects(pieces in prop::collection::vec(piece_with_subject(), 0..7)) {
            let p: String = pieces.iter().map(|(p, _)| p.as_str()).collect();
            let s: String = pieces.iter().map(|(_, s)| s.as_str()).collect();
            let sc: Vec<char> = s.chars().collect();
            let pc: Vec<char> = p.chars().collect();
            prop_assert_eq!(sensitive(&s, &p), oracle(&sc, &pc), "{:?} Like {:?}", s, p);
        }

        #[test]
        fn escaped_string_matches_exactly_itself(s in "\\PC{0,12}", t in "\\PC{0,12}") {
            let p = escape(&s);
            prop_assert!(sensitive(&s, &p));
            prop_assert_eq!(sensitive(&t, &p), t == s);
        }

        #[test]
        fn escaped_string_matches_itself_from_a_special_alphabet(
            s in "[\\[\\]*?#!a-c-]{0,12}", t in "[\\[\\]*?#!a-c-]{0,12}"
        ) {
            let p = escape(&s);
            prop_assert!(sensitive(&s, &p));
            prop_assert_eq!(sensitive(&t, &p), t == s);
        }

        #[test]
        fn star_matches_everything(s in "\\PC{0,20}") {
            prop_assert!(sensitive(&s, "*"));
            prop_assert!(match_pattern(&s, "*", MatchCase::Insensitive));
        }

        #[test]
        fn agrees_with_backtracking_oracle(s in subject_strategy(), p in pattern_strategy()) {
            let sc: Vec<char> = s.chars().collect();
            let pc: Vec<char> = p.chars().collect();
            prop_assert_eq!(sensitive(&s, &p), oracle(&sc, &pc), "{:?} Like {:?}", s, p);
        }

        #[test]
        fn insensitive_equals_sensitive_on_uppercased_inputs(s in "[a-cA-C1?*]{0,8}", p in "[a-cA-C1?*#]{0,6}") {
            let ci = match_pattern(&s, &p, MatchCase::Insensitive);
            let upper_both = sensitive(&s.to_uppercase(), &p.to_uppercase());
            prop_assert_eq!(ci, upper_both);
        }
    }
}
