//! Drift check between the IDL the proxy/stub DLL is built from (`idl/*.idl`) and the Rust
//! definitions of the same interfaces (`crates/ctopc-com/src/com/interfaces/**.rs`).
//!
//! A vtable mismatch between the two is silent memory corruption across processes, so this
//! test fails, with one line per discrepancy, when
//! * an interface is defined on one side only,
//! * an IID differs (compared case-insensitively),
//! * the base interface differs,
//! * the methods differ in name, order or number of parameters (`&self` not counted),
//! * a component category GUID (`CATID_*`) defined in the IDL is missing or different in Rust.
//!
//! Both parsers are small tokenizers, std only: the IDL side understands MIDL attributes,
//! comments, `cpp_quote`, `typedef`s inside interfaces, forward declarations, `library` /
//! `coclass` blocks and CATIDs given as `DEFINE_GUID` or as `CATID_*` placeholder interfaces;
//! the Rust side understands `#[interface("…")]` / `#[windows_core::interface("…")]` traits and
//! `const CATID_*: GUID = GUID::from_u128(0x…)` (or `from_values`, or a string).

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::fs;
use std::path::{Path, PathBuf};

// ---------------------------------------------------------------------------------------
// Model
// ---------------------------------------------------------------------------------------

#[derive(Debug, Clone, PartialEq, Eq)]
struct Method {
    name: String,
    params: usize,
}

#[derive(Debug, Clone)]
struct Interface {
    name: String,
    /// Lower-case `xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxxxx`, or the raw text if malformed.
    iid: String,
    base: Option<String>,
    methods: Vec<Method>,
    /// `file:line` of the definition, for messages.
    origin: String,
}

impl Interface {
    fn same_shape(&self, other: &Interface) -> bool {
        self.iid == other.iid && self.base == other.base && self.methods == other.methods
    }
}

#[derive(Debug, Default)]
struct Definitions {
    interfaces: BTreeMap<String, Interface>,
    /// CATID name -> (GUID, origin).
    catids: BTreeMap<String, (String, String)>,
    /// Problems found while parsing (conflicting duplicates, malformed declarations).
    problems: Vec<String>,
}

impl Definitions {
    fn add_interface(&mut self, itf: Interface) {
        match self.interfaces.get(&itf.name) {
            Some(existing) if !existing.same_shape(&itf) => self.problems.push(format!(
                "{} is defined twice, differently: {} and {}",
                itf.name, existing.origin, itf.origin
            )),
            Some(_) => {}
            None => {
                self.interfaces.insert(itf.name.clone(), itf);
            }
        }
    }

    fn add_catid(&mut self, name: String, guid: String, origin: String) {
        match self.catids.get(&name) {
            Some((existing, first)) if *existing != guid => self.problems.push(format!(
                "{name} is defined twice, differently: {existing} ({first}) and {guid} ({origin})"
            )),
            Some(_) => {}
            None => {
                self.catids.insert(name, (guid, origin));
            }
        }
    }
}

// ---------------------------------------------------------------------------------------
// Tokens (shared by both parsers)
// ---------------------------------------------------------------------------------------

#[derive(Debug, Clone, PartialEq, Eq)]
enum Tok {
    /// Identifier, keyword or number: a run of `[A-Za-z0-9_]`.
    Word(String),
    /// String literal contents (escapes kept verbatim).
    Str(String),
    /// Any other single non-blank character.
    Punct(char),
}

#[derive(Debug, Clone)]
struct Token {
    tok: Tok,
    line: usize,
}

impl Token {
    fn is_punct(&self, c: char) -> bool {
        self.tok == Tok::Punct(c)
    }
    fn is_word(&self, w: &str) -> bool {
        matches!(&self.tok, Tok::Word(s) if s == w)
    }
    fn word(&self) -> Option<&str> {
        match &self.tok {
            Tok::Word(s) => Some(s),
            _ => None,
        }
    }
    fn text(&self) -> String {
        match &self.tok {
            Tok::Word(s) | Tok::Str(s) => s.clone(),
            Tok::Punct(c) => c.to_string(),
        }
    }
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Lang {
    Idl,
    Rust,
}

fn is_word_char(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_'
}

/// Splits `src` into tokens, dropping comments (and, for IDL, preprocessor lines).
fn tokenize(src: &str, lang: Lang) -> Vec<Token> {
    let chars: Vec<char> = src.chars().collect();
    let mut out = Vec::new();
    let mut i = 0;
    let mut line = 1;
    let mut at_line_start = true;
    while i < chars.len() {
        let c = chars[i];
        let next = chars.get(i + 1).copied();
        if c == '\n' {
            line += 1;
            at_line_start = true;
            i += 1;
            continue;
        }
        if c.is_whitespace() {
            i += 1;
            continue;
        }
        if lang == Lang::Idl && at_line_start && c == '#' {
            // Preprocessor line, with backslash continuations.
            while i < chars.len() && chars[i] != '\n' {
                if chars[i] == '\\' && chars.get(i + 1) == Some(&'\n') {
                    line += 1;
                    i += 1;
                }
                i += 1;
            }
            continue;
        }
        at_line_start = false;
        if c == '/' && next == Some('/') {
            while i < chars.len() && chars[i] != '\n' {
                i += 1;
            }
            continue;
        }
        if c == '/' && next == Some('*') {
            // Rust block comments nest; IDL ones do not.
            let mut depth = 1;
            i += 2;
            while i < chars.len() && depth > 0 {
                if chars[i] == '\n' {
                    line += 1;
                }
                if chars[i] == '*' && chars.get(i + 1) == Some(&'/') {
                    depth -= 1;
                    i += 2;
                } else if lang == Lang::Rust && chars[i] == '/' && chars.get(i + 1) == Some(&'*') {
                    depth += 1;
                    i += 2;
                } else {
                    i += 1;
                }
            }
            continue;
        }
        if lang == Lang::Rust && c == 'r' && (next == Some('"') || next == Some('#')) {
            // Raw string r"…" / r#"…"#.
            let mut j = i + 1;
            let mut hashes = 0;
            while chars.get(j) == Some(&'#') {
                hashes += 1;
                j += 1;
            }
            if chars.get(j) == Some(&'"') {
                let start_line = line;
                let mut k = j + 1;
                let mut content = String::new();
                while k < chars.len() {
                    if chars[k] == '"' && (1..=hashes).all(|h| chars.get(k + h) == Some(&'#')) {
                        break;
                    }
                    if chars[k] == '\n' {
                        line += 1;
                    }
                    content.push(chars[k]);
                    k += 1;
                }
                out.push(Token {
                    tok: Tok::Str(content),
                    line: start_line,
                });
                i = k + 1 + hashes;
                continue;
            }
        }
        if c == '"' {
            let start_line = line;
            let mut content = String::new();
            i += 1;
            while i < chars.len() && chars[i] != '"' {
                if chars[i] == '\\' && i + 1 < chars.len() {
                    content.push(chars[i]);
                    i += 1;
                }
                if chars[i] == '\n' {
                    line += 1;
                }
                content.push(chars[i]);
                i += 1;
            }
            i += 1;
            out.push(Token {
                tok: Tok::Str(content),
                line: start_line,
            });
            continue;
        }
        if c == '\'' {
            // Char literal ('x', '\n', '\u{..}'); otherwise a Rust lifetime / label.
            let close = if next == Some('\\') {
                (i + 2..chars.len().min(i + 12)).find(|&k| chars[k] == '\'')
            } else if chars.get(i + 2) == Some(&'\'') {
                Some(i + 2)
            } else {
                None
            };
            if let Some(end) = close {
                out.push(Token {
                    tok: Tok::Str(chars[i + 1..end].iter().collect()),
                    line,
                });
                i = end + 1;
                continue;
            }
            out.push(Token {
                tok: Tok::Punct('\''),
                line,
            });
            i += 1;
            continue;
        }
        if is_word_char(c) {
            let start = i;
            while i < chars.len() && is_word_char(chars[i]) {
                i += 1;
            }
            out.push(Token {
                tok: Tok::Word(chars[start..i].iter().collect()),
                line,
            });
            continue;
        }
        out.push(Token {
            tok: Tok::Punct(c),
            line,
        });
        i += 1;
    }
    out
}

fn closing(open: char) -> Option<char> {
    match open {
        '(' => Some(')'),
        '[' => Some(']'),
        '{' => Some('}'),
        _ => None,
    }
}

/// For `toks[start]` an opening `(`, `[` or `{`: the index of its matching closer
/// (or `toks.len()` if unbalanced).
fn matching(toks: &[Token], start: usize) -> usize {
    let mut stack: Vec<char> = Vec::new();
    let mut i = start;
    while i < toks.len() {
        if let Tok::Punct(c) = toks[i].tok {
            if let Some(close) = closing(c) {
                stack.push(close);
            } else if stack.last() == Some(&c) {
                stack.pop();
                if stack.is_empty() {
                    return i;
                }
            }
        }
        i += 1;
    }
    toks.len()
}

/// Splits `toks` at top-level occurrences of `sep` (nesting: `()`, `[]`, `{}`, and `<>`
/// when `angles`, where `->` does not close). Empty pieces are dropped.
fn split_top(toks: &[Token], sep: char, angles: bool) -> Vec<&[Token]> {
    let mut pieces = Vec::new();
    let mut depth: i32 = 0;
    let mut start = 0;
    for (i, t) in toks.iter().enumerate() {
        match t.tok {
            Tok::Punct('(' | '[' | '{') => depth += 1,
            Tok::Punct(')' | ']' | '}') => depth -= 1,
            Tok::Punct('<') if angles => depth += 1,
            Tok::Punct('>') if angles && !(i > 0 && toks[i - 1].is_punct('-')) => depth -= 1,
            Tok::Punct(c) if c == sep && depth == 0 => {
                if i > start {
                    pieces.push(&toks[start..i]);
                }
                start = i + 1;
            }
            _ => {}
        }
    }
    if start < toks.len() {
        pieces.push(&toks[start..]);
    }
    pieces
}

// ---------------------------------------------------------------------------------------
// GUIDs
// ---------------------------------------------------------------------------------------

/// Canonical lower-case form of a `8-4-4-4-12` GUID text (braces and case ignored); `None`
/// if it is not one.
fn canonical_guid(text: &str) -> Option<String> {
    let t = text
        .trim()
        .trim_start_matches('{')
        .trim_end_matches('}')
        .to_ascii_lowercase();
    let parts: Vec<&str> = t.split('-').collect();
    let lens = [8, 4, 4, 4, 12];
    let ok = parts.len() == 5
        && parts
            .iter()
            .zip(lens)
            .all(|(p, n)| p.len() == n && p.chars().all(|c| c.is_ascii_hexdigit()));
    ok.then_some(t)
}

fn guid_from_u128_hex(hex: &str) -> Option<String> {
    let digits: String = hex
        .trim_start_matches("0x")
        .chars()
        .filter(|&c| c != '_')
        .collect();
    let digits = digits.trim_end_matches("u128");
    if digits.len() != 32 || !digits.chars().all(|c| c.is_ascii_hexdigit()) {
        return None;
    }
    let d = digits.to_ascii_lowercase();
    Some(format!(
        "{}-{}-{}-{}-{}",
        &d[0..8],
        &d[8..12],
        &d[12..16],
        &d[16..20],
        &d[20..32]
    ))
}

fn parse_int(word: &str) -> Option<u64> {
    let w = word.trim_end_matches(['u', 'U', 'l', 'L']);
    let w = w.split("_u").next().unwrap_or(w); // Rust suffixes: 0x12_u8
    if let Some(h) = w.strip_prefix("0x").or_else(|| w.strip_prefix("0X")) {
        u64::from_str_radix(&h.replace('_', ""), 16).ok()
    } else {
        w.replace('_', "").parse().ok()
    }
}

/// `DEFINE_GUID` / `GUID::from_values` argument order: u32, u16, u16, 8 × u8.
fn guid_from_fields(nums: &[u64]) -> Option<String> {
    if nums.len() != 11
        || nums[0] > 0xFFFF_FFFF
        || nums[1] > 0xFFFF
        || nums[2] > 0xFFFF
        || nums[3..].iter().any(|&b| b > 0xFF)
    {
        return None;
    }
    let mut s = format!(
        "{:08x}-{:04x}-{:04x}-{:02x}{:02x}-",
        nums[0], nums[1], nums[2], nums[3], nums[4]
    );
    for b in &nums[5..] {
        let _ = write!(s, "{b:02x}");
    }
    Some(s)
}

// ---------------------------------------------------------------------------------------
// IDL parser
// ---------------------------------------------------------------------------------------

fn parse_idl(src: &str, file: &str, defs: &mut Definitions) {
    let toks = tokenize(src, Lang::Idl);
    let mut attrs: Option<(usize, usize)> = None; // last `[ … ]` group (exclusive bounds)
    let mut i = 0;
    while i < toks.len() {
        let t = &toks[i];
        if t.is_punct('[') {
            let end = matching(&toks, i);
            attrs = Some((i + 1, end));
            i = end + 1;
            continue;
        }
        if t.is_word("cpp_quote") && toks.get(i + 1).is_some_and(|n| n.is_punct('(')) {
            let end = matching(&toks, i + 1);
            for s in &toks[i + 2..end] {
                if let Tok::Str(text) = &s.tok {
                    catids_in_cpp_quote(text, &format!("{file}:{}", s.line), defs);
                }
            }
            attrs = None;
            i = end + 1;
            continue;
        }
        if t.is_word("interface") || t.is_word("dispinterface") {
            let Some(name) = toks.get(i + 1).and_then(Token::word) else {
                i += 1;
                continue;
            };
            let origin = format!("{file}:{}", toks[i + 1].line);
            let mut j = i + 2;
            let mut base = None;
            if toks.get(j).is_some_and(|n| n.is_punct(':')) {
                base = toks.get(j + 1).and_then(Token::word).map(str::to_string);
                j += 2;
            }
            if !toks.get(j).is_some_and(|n| n.is_punct('{')) {
                // Forward declaration or reference (`interface IFoo;` in a coclass).
                attrs = None;
                i = j;
                continue;
            }
            let end = matching(&toks, j);
            let uuid = attrs
                .map(|(a, b)| uuid_in_attrs(&toks[a..b]))
                .unwrap_or_default();
            if name.starts_with("CATID_") {
                // OPC Foundation style: `[uuid(…)] interface CATID_OPCDAServer10 {}`.
                defs.add_catid(name.to_string(), uuid, origin);
            } else {
                if uuid.is_empty() {
                    defs.problems
                        .push(format!("{name} ({origin}) has no uuid attribute"));
                }
                let methods = idl_methods(&toks[j + 1..end]);
                defs.add_interface(Interface {
                    name: name.to_string(),
                    iid: uuid,
                    base,
                    methods,
                    origin,
                });
            }
            attrs = None;
            i = end + 1;
            continue;
        }
        if t.is_punct(';') || t.is_punct('{') || t.is_punct('}') {
            attrs = None;
        }
        i += 1;
    }
}

/// The uuid inside an attribute list such as `object, uuid(39c13a4d-…), pointer_default(unique)`.
fn uuid_in_attrs(toks: &[Token]) -> String {
    for (k, t) in toks.iter().enumerate() {
        if t.is_word("uuid") && toks.get(k + 1).is_some_and(|n| n.is_punct('(')) {
            let end = matching(toks, k + 1);
            let raw: String = toks[k + 2..end.min(toks.len())]
                .iter()
                .map(Token::text)
                .collect();
            return canonical_guid(&raw).unwrap_or(raw);
        }
    }
    String::new()
}

/// CATIDs declared in C text: `DEFINE_GUID(CATID_X, 0x…, …)` or `CATID_X = {0x…, …}`.
fn catids_in_cpp_quote(text: &str, origin: &str, defs: &mut Definitions) {
    let toks = tokenize(text, Lang::Idl);
    for (k, t) in toks.iter().enumerate() {
        let Some(name) = t.word().filter(|w| w.starts_with("CATID_")) else {
            continue;
        };
        // Numbers up to the end of this statement / macro call.
        let mut nums = Vec::new();
        for u in &toks[k + 1..] {
            if u.is_punct(';') || u.is_punct(')') {
                break;
            }
            if let Some(n) = u.word().and_then(parse_int) {
                nums.push(n);
            }
        }
        if let Some(guid) = guid_from_fields(&nums) {
            defs.add_catid(name.to_string(), guid, origin.to_string());
        }
    }
}

fn idl_methods(body: &[Token]) -> Vec<Method> {
    let mut methods = Vec::new();
    let mut i = 0;
    while i < body.len() {
        let t = &body[i];
        if t.is_punct('[') {
            i = matching(body, i) + 1; // method attributes: [local], [call_as(…)], …
            continue;
        }
        if t.is_word("cpp_quote") && body.get(i + 1).is_some_and(|n| n.is_punct('(')) {
            i = matching(body, i + 1) + 1;
            continue;
        }
        // One declaration, up to `;` at depth 0.
        let mut end = i;
        let mut depth = 0;
        while end < body.len() {
            match body[end].tok {
                Tok::Punct('(' | '[' | '{') => depth += 1,
                Tok::Punct(')' | ']' | '}') => depth -= 1,
                Tok::Punct(';') if depth == 0 => break,
                _ => {}
            }
            end += 1;
        }
        let decl = &body[i..end];
        i = end + 1;
        let Some(first) = decl.first() else { continue };
        if ["typedef", "const", "import", "midl_pragma"]
            .iter()
            .any(|k| first.is_word(k))
        {
            continue;
        }
        let Some(open) = decl.iter().position(|t| t.is_punct('(')) else {
            continue;
        };
        let Some(name) = open.checked_sub(1).and_then(|k| decl[k].word()) else {
            continue;
        };
        let close = matching(decl, open);
        let inner = &decl[open + 1..close.min(decl.len())];
        let params = split_top(inner, ',', false);
        let count = if params.len() == 1 && params[0].len() == 1 && params[0][0].is_word("void") {
            0
        } else {
            params.len()
        };
        methods.push(Method {
            name: name.to_string(),
            params: count,
        });
    }
    methods
}

// ---------------------------------------------------------------------------------------
// Rust parser
// ---------------------------------------------------------------------------------------

fn parse_rust(src: &str, file: &str, defs: &mut Definitions) {
    let toks = tokenize(src, Lang::Rust);
    let mut i = 0;
    while i < toks.len() {
        // `#[ … interface("uuid") … ]`
        if toks[i].is_punct('#') && toks.get(i + 1).is_some_and(|t| t.is_punct('[')) {
            let end = matching(&toks, i + 1);
            let attr = &toks[i + 2..end.min(toks.len())];
            let is_interface = attr
                .iter()
                .position(|t| t.is_word("interface"))
                .filter(|&k| k + 1 == attr.len() || attr[k + 1].is_punct('('))
                .filter(|&k| k == 0 || attr[k - 1].is_punct(':'));
            if let Some(k) = is_interface {
                let iid = match attr.get(k + 2).map(|t| &t.tok) {
                    Some(Tok::Str(s)) => canonical_guid(s).unwrap_or_else(|| s.clone()),
                    _ => String::new(),
                };
                i = rust_trait(&toks, end + 1, iid, file, defs);
                continue;
            }
            i = end + 1;
            continue;
        }
        if toks[i].is_word("const") {
            if let Some(name) = toks
                .get(i + 1)
                .and_then(Token::word)
                .filter(|n| n.starts_with("CATID_"))
            {
                let mut end = i;
                while end < toks.len() && !toks[end].is_punct(';') {
                    end += 1;
                }
                let origin = format!("{file}:{}", toks[i + 1].line);
                match rust_guid_value(&toks[i + 2..end]) {
                    Some(guid) => defs.add_catid(name.to_string(), guid, origin),
                    None => defs
                        .problems
                        .push(format!("{name} ({origin}): cannot read its GUID value")),
                }
                i = end;
                continue;
            }
        }
        i += 1;
    }
}

/// The value of `const CATID_X: GUID = <value>;` (tokens after the name).
fn rust_guid_value(toks: &[Token]) -> Option<String> {
    for (k, t) in toks.iter().enumerate() {
        if let Tok::Str(s) = &t.tok {
            if let Some(g) = canonical_guid(s) {
                return Some(g);
            }
        }
        if t.is_word("from_u128") {
            return toks
                .get(k + 2)
                .and_then(Token::word)
                .and_then(guid_from_u128_hex);
        }
        if t.is_word("from_values") {
            let nums: Vec<u64> = toks[k + 1..]
                .iter()
                .filter_map(|t| t.word().and_then(parse_int))
                .collect();
            return guid_from_fields(&nums);
        }
    }
    None
}

/// Parses `[attributes] [pub] unsafe trait Name: Base { fn …; }` from `start`; returns the
/// index after it.
fn rust_trait(
    toks: &[Token],
    start: usize,
    iid: String,
    file: &str,
    defs: &mut Definitions,
) -> usize {
    let mut i = start;
    // Further attributes (#[doc], …).
    while toks.get(i).is_some_and(|t| t.is_punct('#'))
        && toks.get(i + 1).is_some_and(|t| t.is_punct('['))
    {
        i = matching(toks, i + 1) + 1;
    }
    let Some(trait_at) = (i..toks.len().min(i + 8)).find(|&k| toks[k].is_word("trait")) else {
        defs.problems.push(format!(
            "{file}:{}: #[interface] not followed by a trait",
            toks.get(start).map_or(0, |t| t.line)
        ));
        return start;
    };
    let Some(name) = toks.get(trait_at + 1).and_then(Token::word) else {
        return trait_at + 1;
    };
    let origin = format!("{file}:{}", toks[trait_at + 1].line);
    let mut j = trait_at + 2;
    let mut base = None;
    if toks.get(j).is_some_and(|t| t.is_punct(':')) {
        // A path such as `windows_core::IUnknown`: keep its last segment.
        j += 1;
        while let Some(w) = toks.get(j).and_then(Token::word) {
            base = Some(w.to_string());
            if toks.get(j + 1).is_some_and(|t| t.is_punct(':'))
                && toks.get(j + 2).is_some_and(|t| t.is_punct(':'))
            {
                j += 3;
            } else {
                j += 1;
                break;
            }
        }
    }
    while j < toks.len() && !toks[j].is_punct('{') {
        j += 1;
    }
    let end = matching(toks, j);
    let body = &toks[(j + 1).min(toks.len())..end.min(toks.len())];
    let mut methods = Vec::new();
    let mut k = 0;
    while k < body.len() {
        if body[k].is_word("fn") {
            if let (Some(mname), Some(open)) =
                (body.get(k + 1).and_then(Token::word), body.get(k + 2))
            {
                if open.is_punct('(') {
                    let close = matching(body, k + 2);
                    let params = split_top(&body[k + 3..close.min(body.len())], ',', true);
                    let count = params.iter().filter(|p| !is_receiver(p)).count();
                    methods.push(Method {
                        name: mname.to_string(),
                        params: count,
                    });
                    k = close;
                }
            }
        }
        k += 1;
    }
    defs.add_interface(Interface {
        name: name.to_string(),
        iid,
        base,
        methods,
        origin,
    });
    end + 1
}

/// `self`, `&self`, `&mut self`, `&'a self`, `self: &Self`.
fn is_receiver(param: &[Token]) -> bool {
    let words: Vec<&str> = param.iter().filter_map(Token::word).collect();
    words.first() == Some(&"self")
        || (words.contains(&"self") && !param.iter().any(|t| t.is_punct(':')))
}

// ---------------------------------------------------------------------------------------
// Comparison
// ---------------------------------------------------------------------------------------

fn compare(idl: &Definitions, rust: &Definitions) -> Vec<String> {
    let mut out = Vec::new();
    for p in &idl.problems {
        out.push(format!("IDL: {p}"));
    }
    for p in &rust.problems {
        out.push(format!("Rust: {p}"));
    }
    for (name, i) in &idl.interfaces {
        let Some(r) = rust.interfaces.get(name) else {
            out.push(format!(
                "{name}: defined in the IDL ({}) but not in Rust",
                i.origin
            ));
            continue;
        };
        if i.iid != r.iid {
            out.push(format!(
                "{name}: IID differs: IDL {} ({}) vs Rust {} ({})",
                show(&i.iid),
                i.origin,
                show(&r.iid),
                r.origin
            ));
        }
        if i.base != r.base {
            out.push(format!(
                "{name}: base interface differs: IDL {} ({}) vs Rust {} ({})",
                i.base.as_deref().unwrap_or("(none)"),
                i.origin,
                r.base.as_deref().unwrap_or("(none)"),
                r.origin
            ));
        }
        if i.methods != r.methods {
            out.push(method_diff(name, i, r));
        }
    }
    for (name, r) in &rust.interfaces {
        if !idl.interfaces.contains_key(name) {
            out.push(format!(
                "{name}: defined in Rust ({}) but not in the IDL",
                r.origin
            ));
        }
    }
    for (name, (guid, origin)) in &idl.catids {
        match rust.catids.get(name) {
            None => out.push(format!(
                "{name}: defined in the IDL ({origin}) but not in Rust"
            )),
            Some((rguid, rorigin)) if rguid != guid => out.push(format!(
                "{name}: GUID differs: IDL {guid} ({origin}) vs Rust {rguid} ({rorigin})"
            )),
            Some(_) => {}
        }
    }
    out
}

fn show(iid: &str) -> &str {
    if iid.is_empty() {
        "(none)"
    } else {
        iid
    }
}

/// A side-by-side table of the vtable slots after IUnknown, `!` marking differing rows.
fn method_diff(name: &str, idl: &Interface, rust: &Interface) -> String {
    let cell = |m: Option<&Method>| {
        m.map_or_else(
            || "-".to_string(),
            |m| format!("{}({} params)", m.name, m.params),
        )
    };
    let mut s = format!(
        "{name}: methods differ (IDL {} vs Rust {}):\n",
        idl.origin, rust.origin
    );
    let _ = writeln!(s, "        {:>3}  {:<34} Rust", "#", "IDL");
    for k in 0..idl.methods.len().max(rust.methods.len()) {
        let (a, b) = (idl.methods.get(k), rust.methods.get(k));
        let mark = if a == b { ' ' } else { '!' };
        let _ = writeln!(s, "      {mark} {k:>3}  {:<34} {}", cell(a), cell(b));
    }
    s.trim_end().to_string()
}

// ---------------------------------------------------------------------------------------
// The test
// ---------------------------------------------------------------------------------------

fn workspace_root() -> PathBuf {
    let xtask = Path::new(env!("CARGO_MANIFEST_DIR"));
    xtask
        .parent()
        .map_or_else(|| xtask.to_path_buf(), Path::to_path_buf)
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = fs::read_dir(dir) else {
        return;
    };
    let mut paths: Vec<PathBuf> = entries.filter_map(|e| e.ok().map(|e| e.path())).collect();
    paths.sort();
    for p in paths {
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|e| e == "rs") {
            out.push(p);
        }
    }
}

fn relative(root: &Path, p: &Path) -> String {
    p.strip_prefix(root).unwrap_or(p).display().to_string()
}

#[test]
fn interfaces_match_idl() {
    let root = workspace_root();
    let idl_dir = root.join("idl");
    let rust_dir = root.join("crates/ctopc-com/src/com/interfaces");

    let mut idl = Definitions::default();
    for required in ["opccomn.idl", "opcda.idl"] {
        assert!(
            idl_dir.join(required).is_file(),
            "{} not found: this test compares it with {}",
            relative(&root, &idl_dir.join(required)),
            relative(&root, &rust_dir)
        );
    }
    let mut idl_files: Vec<PathBuf> = fs::read_dir(&idl_dir)
        .expect("read idl/")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "idl"))
        .collect();
    idl_files.sort();
    for f in &idl_files {
        let src = fs::read_to_string(f).unwrap_or_else(|e| panic!("read {}: {e}", f.display()));
        parse_idl(&src, &relative(&root, f), &mut idl);
    }

    let mut rust = Definitions::default();
    let mut files = Vec::new();
    rust_files(&rust_dir, &mut files);
    assert!(
        !files.is_empty(),
        "no Rust sources under {}",
        relative(&root, &rust_dir)
    );
    for f in &files {
        let src = fs::read_to_string(f).unwrap_or_else(|e| panic!("read {}: {e}", f.display()));
        parse_rust(&src, &relative(&root, f), &mut rust);
    }

    // Guard against a parser that silently finds nothing.
    assert!(
        idl.interfaces.len() >= 5,
        "only {} interfaces parsed from idl/*.idl",
        idl.interfaces.len()
    );
    assert!(
        rust.interfaces.len() >= 5,
        "only {} interfaces parsed from Rust",
        rust.interfaces.len()
    );

    let problems = compare(&idl, &rust);
    if !problems.is_empty() {
        let mut msg = format!(
            "{} discrepancies between idl/*.idl ({} interfaces, {} CATIDs) and {} ({} interfaces, {} CATIDs):\n",
            problems.len(),
            idl.interfaces.len(),
            idl.catids.len(),
            relative(&root, &rust_dir),
            rust.interfaces.len(),
            rust.catids.len()
        );
        for p in &problems {
            let _ = writeln!(msg, "  - {p}");
        }
        panic!("{msg}");
    }
}

// ---------------------------------------------------------------------------------------
// Parser unit tests
// ---------------------------------------------------------------------------------------

const IDL_SAMPLE: &str = r##"
import "unknwn.idl";
#include "something.h"
cpp_quote("DEFINE_GUID(CATID_OPCDAServer20, 0x63d5f432, 0xcfe4, 0x11d1, 0xb2, 0xc8, 0x00, 0x60, 0x08, 0x3b, 0xa1, 0xfb);")
cpp_quote("#define CATID_OPCDAServer10 IID_CATID_OPCDAServer10")
interface IForward;
[
    uuid(63D5F430-CFE4-11d1-B2C8-0060083BA1FB)
]
interface CATID_OPCDAServer10 { }

/* A block comment mentioning interface IFake : IUnknown { HRESULT X(); } */
[
    object,
    uuid(F31DFDE2-07B6-11d2-B2D8-0060083BA1FB), // IOPCCommon
    pointer_default(unique)
]
interface IOPCCommon : IUnknown
{
    typedef [unique] IOPCCommon *LPOPCCOMMON;
    HRESULT SetLocaleID([in] LCID dwLcid);
    HRESULT QueryAvailableLocaleIDs(
        [out] DWORD *pdwCount,
        [out, size_is(,*pdwCount)] LCID **pdwLcid);
    cpp_quote("/* ; ( */")
    [local] HRESULT Reset(void);
    HRESULT Nothing();
}

library L
{
    coclass C { [default] interface IOPCCommon; };
    [object, uuid(39c13a52-011e-11d0-9675-0020afd8adb3)]
    interface IOPCSyncIO2 : IOPCSyncIO
    {
        HRESULT Read([in] DWORD dwCount, [in, size_is(dwCount)] OPCHANDLE *phServer);
    };
}
"##;

#[test]
fn idl_parser_reads_interfaces_methods_and_catids() {
    let mut d = Definitions::default();
    parse_idl(IDL_SAMPLE, "sample.idl", &mut d);
    assert!(d.problems.is_empty(), "{:?}", d.problems);
    let names: Vec<&str> = d.interfaces.keys().map(String::as_str).collect();
    assert_eq!(names, ["IOPCCommon", "IOPCSyncIO2"]);

    let c = &d.interfaces["IOPCCommon"];
    assert_eq!(c.iid, "f31dfde2-07b6-11d2-b2d8-0060083ba1fb");
    assert_eq!(c.base.as_deref(), Some("IUnknown"));
    let methods: Vec<(&str, usize)> = c
        .methods
        .iter()
        .map(|m| (m.name.as_str(), m.params))
        .collect();
    assert_eq!(
        methods,
        [
            ("SetLocaleID", 1),
            ("QueryAvailableLocaleIDs", 2),
            ("Reset", 0),
            ("Nothing", 0)
        ]
    );
    assert_eq!(c.origin, "sample.idl:18");

    let s = &d.interfaces["IOPCSyncIO2"];
    assert_eq!(s.base.as_deref(), Some("IOPCSyncIO"));
    assert_eq!(
        s.methods,
        [Method {
            name: "Read".into(),
            params: 2
        }]
    );

    assert_eq!(
        d.catids["CATID_OPCDAServer10"].0,
        "63d5f430-cfe4-11d1-b2c8-0060083ba1fb"
    );
    assert_eq!(
        d.catids["CATID_OPCDAServer20"].0,
        "63d5f432-cfe4-11d1-b2c8-0060083ba1fb"
    );
    assert_eq!(d.catids.len(), 2);
}

const RUST_SAMPLE: &str = r##"
use windows_core::*;
/// Doc comment with #[interface("00000000-0000-0000-0000-000000000000")] in it.
#[windows_core::interface("F31DFDE2-07B6-11D2-B2D8-0060083BA1FB")]
pub unsafe trait IOPCCommon: windows_core::IUnknown {
    /// Sets the locale.
    pub fn SetLocaleID(&self, dwLcid: u32) -> Result<()>;
    pub fn QueryAvailableLocaleIDs(
        &self,
        pdwCount: *mut u32,
        pdwLcid: *mut *mut u32,
    ) -> HRESULT;
    fn Reset(&self) -> Result<()>;
    pub fn Generic(&self, a: Option<Foo<A, B>>, f: fn(u32, u32) -> u32, s: &'static str);
}

#[interface("39c13a52-011e-11d0-9675-0020afd8adb3")]
unsafe trait IOPCSyncIO2: IOPCSyncIO {
    fn Read(&self, c: u32, h: *const u32) -> HRESULT;
}

const S: &str = r#"#[interface("x")] unsafe trait INot: IUnknown {}"#;
const C: char = '{';
pub const CATID_OPCDAServer10: GUID = GUID::from_u128(0x63d5f430_cfe4_11d1_b2c8_0060083ba1fb);
pub const CATID_OPCDAServer20: GUID =
    GUID::from_values(0x63d5f432, 0xcfe4, 0x11d1, [0xb2, 0xc8, 0x00, 0x60, 0x08, 0x3b, 0xa1, 0xfb]);
"##;

#[test]
fn rust_parser_reads_traits_methods_and_catids() {
    let mut d = Definitions::default();
    parse_rust(RUST_SAMPLE, "sample.rs", &mut d);
    assert!(d.problems.is_empty(), "{:?}", d.problems);
    let names: Vec<&str> = d.interfaces.keys().map(String::as_str).collect();
    assert_eq!(names, ["IOPCCommon", "IOPCSyncIO2"]);

    let c = &d.interfaces["IOPCCommon"];
    assert_eq!(c.iid, "f31dfde2-07b6-11d2-b2d8-0060083ba1fb");
    assert_eq!(c.base.as_deref(), Some("IUnknown"));
    let methods: Vec<(&str, usize)> = c
        .methods
        .iter()
        .map(|m| (m.name.as_str(), m.params))
        .collect();
    assert_eq!(
        methods,
        [
            ("SetLocaleID", 1),
            ("QueryAvailableLocaleIDs", 2),
            ("Reset", 0),
            ("Generic", 3)
        ]
    );

    assert_eq!(
        d.interfaces["IOPCSyncIO2"].base.as_deref(),
        Some("IOPCSyncIO")
    );
    assert_eq!(
        d.catids["CATID_OPCDAServer10"].0,
        "63d5f430-cfe4-11d1-b2c8-0060083ba1fb"
    );
    assert_eq!(
        d.catids["CATID_OPCDAServer20"].0,
        "63d5f432-cfe4-11d1-b2c8-0060083ba1fb"
    );
}

#[test]
fn compare_reports_every_kind_of_drift() {
    let mut idl = Definitions::default();
    parse_idl(
        r#"
        [object, uuid(00000000-0000-0000-0000-0000000000AA)] interface IA : IUnknown { HRESULT X([in] int a); HRESULT Y(); }
        [object, uuid(00000000-0000-0000-0000-0000000000BB)] interface IB : IUnknown { HRESULT X(); }
        [object, uuid(00000000-0000-0000-0000-0000000000CC)] interface IOnlyIdl : IUnknown { }
        [object, uuid(00000000-0000-0000-0000-0000000000DD)] interface ISame : IA { HRESULT Z(); }
        cpp_quote("DEFINE_GUID(CATID_X, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11);")
        "#,
        "a.idl",
        &mut idl,
    );
    let mut rust = Definitions::default();
    parse_rust(
        r#"
        #[interface("00000000-0000-0000-0000-0000000000aa")] pub unsafe trait IA: IUnknown { fn Y(&self); fn X(&self, a: i32, b: i32); }
        #[interface("00000000-0000-0000-0000-0000000000bf")] pub unsafe trait IB: IDispatch { fn X(&self); }
        #[interface("00000000-0000-0000-0000-0000000000ee")] pub unsafe trait IOnlyRust: IUnknown { }
        #[interface("00000000-0000-0000-0000-0000000000DD")] pub unsafe trait ISame: IA { fn Z(&self); }
        const CATID_X: GUID = GUID::from_u128(0x00000001_0002_0003_0405_060708090a0c);
        "#,
        "a.rs",
        &mut rust,
    );
    let problems = compare(&idl, &rust);
    let text = problems.join("\n");
    assert_eq!(problems.len(), 6, "{text}");
    assert!(text.contains("IA: methods differ"), "{text}");
    assert!(text.contains("!   0  X(1 params)"), "{text}");
    assert!(text.contains("Y(0 params)"), "{text}");
    assert!(
        text.contains("IB: IID differs: IDL 00000000-0000-0000-0000-0000000000bb"),
        "{text}"
    );
    assert!(
        text.contains(
            "IB: base interface differs: IDL IUnknown (a.idl:3) vs Rust IDispatch (a.rs:3)"
        ),
        "{text}"
    );
    assert!(
        text.contains("IOnlyIdl: defined in the IDL (a.idl:4) but not in Rust"),
        "{text}"
    );
    assert!(
        text.contains("IOnlyRust: defined in Rust (a.rs:4) but not in the IDL"),
        "{text}"
    );
    assert!(
        text.contains("CATID_X: GUID differs: IDL 00000001-0002-0003-0405-060708090a0b"),
        "{text}"
    );
    assert!(!text.contains("ISame"), "{text}");
}

#[test]
fn guid_helpers() {
    assert_eq!(
        canonical_guid("{39C13A4D-011E-11D0-9675-0020AFD8ADB3}").as_deref(),
        Some("39c13a4d-011e-11d0-9675-0020afd8adb3")
    );
    assert_eq!(canonical_guid("39C13A4D-011E-11D0-9675-0020AFD8ADB"), None);
    assert_eq!(
        guid_from_u128_hex("0x39c13a4d_011e_11d0_9675_0020afd8adb3").as_deref(),
        Some("39c13a4d-011e-11d0-9675-0020afd8adb3")
    );
}
