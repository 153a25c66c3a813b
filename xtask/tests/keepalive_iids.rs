//! Drift check of the Wine keep-alive's IID lists against the interfaces our COM objects
//! implement.
//!
//! Under Wine, a server process keeps every IID of `SERVER_IIDS` registered with the RPC
//! runtime for its whole life, and a client process every IID of `CLIENT_IIDS` (the
//! keep-alive of `crates/ctopc-com`, docs/limits.md "The soak stall"). An interface that an
//! object hands out of the process and that the list lacks brings back the combase deadlock
//! the keep-alive dodges, silently. This test fails, one line per interface, when an
//! interface of an `#[implement(...)]` list is not in the list of its process's role:
//! - **server**: the objects of `crates/ctopc-com/src` and `crates/serverlist/src`, checked
//!   against `SERVER_IIDS`;
//! - **client**: the sinks of the client library (a `client` module of
//!   `crates/ctopc-com/src`, or `crates/opc-client/src`), checked against `CLIENT_IIDS`.
//!
//! `IUnknown` counts as implemented by every object. Objects inside `#[cfg(test)] mod` blocks
//! are in-process test doubles and are left out. Interfaces are compared by IID: the
//! `#[interface("…")]` traits of the scanned sources give ours (the `Raw*` redefinitions of
//! standard interfaces included), [`WINDOWS_IIDS`] the ones the `windows` crate defines.
//! The lists are read from the one file under `crates/ctopc-com/src` that defines
//! `SERVER_IIDS`, wherever it lives. The scanner is a small tokenizer, std only.

use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};

/// Interfaces of the `windows` crate named in the lists or in `#[implement]`: their IIDs,
/// from the Windows SDK headers (`unknwn.idl`, `objidl.idl`, `ocidl.idl`, `comcat.idl`).
const WINDOWS_IIDS: &[(&str, &str)] = &[
    ("IUnknown", "00000000-0000-0000-c000-000000000046"),
    ("IClassFactory", "00000001-0000-0000-c000-000000000046"),
    ("IEnumUnknown", "00000100-0000-0000-c000-000000000046"),
    ("IEnumString", "00000101-0000-0000-c000-000000000046"),
    ("IEnumSTATDATA", "00000105-0000-0000-c000-000000000046"),
    ("IDataObject", "0000010e-0000-0000-c000-000000000046"),
    ("IAdviseSink", "0000010f-0000-0000-c000-000000000046"),
    ("IEnumGUID", "0002e000-0000-0000-c000-000000000046"),
    (
        "IConnectionPointContainer",
        "b196b284-bab4-101a-b69c-00aa00341d07",
    ),
    (
        "IEnumConnectionPoints",
        "b196b285-bab4-101a-b69c-00aa00341d07",
    ),
    ("IConnectionPoint", "b196b286-bab4-101a-b69c-00aa00341d07"),
    ("IEnumConnections", "b196b287-bab4-101a-b69c-00aa00341d07"),
];

/// Interfaces an object implements that the keep-alive need not hold, each with why: a
/// standard interface whose registration Wine keeps by itself, or one that never crosses
/// the process. None today: every implemented interface is in its role's list.
const NOT_KEPT: &[(&str, &str)] = &[];

// ---------------------------------------------------------------------------------------
// Tokens
// ---------------------------------------------------------------------------------------

#[derive(Debug, Clone, PartialEq, Eq)]
enum Tok {
    Word(String),
    Str(String),
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
}

/// Rust source as tokens, without comments; string and char literals are one token each.
fn tokenize(src: &str) -> Vec<Token> {
    let c: Vec<char> = src.chars().collect();
    let mut out = Vec::new();
    let (mut i, mut line) = (0, 1);
    let word_char = |ch: char| ch.is_ascii_alphanumeric() || ch == '_';
    while i < c.len() {
        let next = c.get(i + 1).copied();
        match c[i] {
            '\n' => {
                line += 1;
                i += 1;
            }
            ch if ch.is_whitespace() => i += 1,
            '/' if next == Some('/') => {
                while i < c.len() && c[i] != '\n' {
                    i += 1;
                }
            }
            '/' if next == Some('*') => {
                let mut depth = 0;
                while i < c.len() {
                    if c[i] == '/' && c.get(i + 1) == Some(&'*') {
                        depth += 1;
                        i += 2;
                    } else if c[i] == '*' && c.get(i + 1) == Some(&'/') {
                        depth -= 1;
                        i += 2;
                        if depth == 0 {
                            break;
                        }
                    } else {
                        line += usize::from(c[i] == '\n');
                        i += 1;
                    }
                }
            }
            'r' | 'b' if raw_string_start(&c, i).is_some() => {
                let (open, hashes) = raw_string_start(&c, i).unwrap_or((i, 0));
                let start_line = line;
                let mut k = open + 1;
                let mut s = String::new();
                while k < c.len()
                    && !(c[k] == '"' && (1..=hashes).all(|h| c.get(k + h) == Some(&'#')))
                {
                    line += usize::from(c[k] == '\n');
                    s.push(c[k]);
                    k += 1;
                }
                out.push(Token {
                    tok: Tok::Str(s),
                    line: start_line,
                });
                i = k + 1 + hashes;
            }
            '"' => {
                let start_line = line;
                let mut s = String::new();
                i += 1;
                while i < c.len() && c[i] != '"' {
                    if c[i] == '\\' {
                        s.push(c[i]);
                        i += 1;
                    }
                    if let Some(&ch) = c.get(i) {
                        line += usize::from(ch == '\n');
                        s.push(ch);
                    }
                    i += 1;
                }
                out.push(Token {
                    tok: Tok::Str(s),
                    line: start_line,
                });
                i += 1;
            }
            '\'' => {
                // A char literal ('x', '\n', '\u{..}'), else a lifetime or a label.
                let close = if next == Some('\\') {
                    (i + 2..c.len().min(i + 12)).find(|&k| c[k] == '\'')
                } else if c.get(i + 2) == Some(&'\'') {
                    Some(i + 2)
                } else {
                    None
                };
                match close {
                    Some(end) => {
                        out.push(Token {
                            tok: Tok::Str(c[i + 1..end].iter().collect()),
                            line,
                        });
                        i = end + 1;
                    }
                    None => {
                        out.push(Token {
                            tok: Tok::Punct('\''),
                            line,
                        });
                        i += 1;
                    }
                }
            }
            ch if word_char(ch) => {
                let start = i;
                while i < c.len() && word_char(c[i]) {
                    i += 1;
                }
                out.push(Token {
                    tok: Tok::Word(c[start..i].iter().collect()),
                    line,
                });
            }
            ch => {
                out.push(Token {
                    tok: Tok::Punct(ch),
                    line,
                });
                i += 1;
            }
        }
    }
    out
}

/// At `r"`, `r#"`, `br"`, …: the index of the opening quote and the number of `#`.
fn raw_string_start(c: &[char], i: usize) -> Option<(usize, usize)> {
    if i > 0 && (c[i - 1].is_ascii_alphanumeric() || c[i - 1] == '_') {
        return None;
    }
    let mut j = i;
    if c[j] == 'b' {
        j += 1;
    }
    if c.get(j) != Some(&'r') {
        return None;
    }
    j += 1;
    let mut hashes = 0;
    while c.get(j) == Some(&'#') {
        hashes += 1;
        j += 1;
    }
    (c.get(j) == Some(&'"')).then_some((j, hashes))
}

/// For `toks[open]` an opening `(`, `[` or `{`: the index of its closer (or the end).
fn matching(toks: &[Token], open: usize) -> usize {
    let mut depth = 0usize;
    for (k, t) in toks.iter().enumerate().skip(open) {
        match t.tok {
            Tok::Punct('(' | '[' | '{') => depth += 1,
            Tok::Punct(')' | ']' | '}') => {
                depth -= 1;
                if depth == 0 {
                    return k;
                }
            }
            _ => {}
        }
    }
    toks.len()
}

/// `toks` split at top-level commas (nesting `()`, `[]`, `{}`, `<>`), empty pieces dropped.
fn split_commas(toks: &[Token]) -> Vec<&[Token]> {
    let mut pieces = Vec::new();
    let (mut depth, mut start) = (0i32, 0);
    for (k, t) in toks.iter().enumerate() {
        match t.tok {
            Tok::Punct('(' | '[' | '{' | '<') => depth += 1,
            Tok::Punct(')' | ']' | '}' | '>') => depth -= 1,
            Tok::Punct(',') if depth == 0 => {
                if k > start {
                    pieces.push(&toks[start..k]);
                }
                start = k + 1;
            }
            _ => {}
        }
    }
    if start < toks.len() {
        pieces.push(&toks[start..]);
    }
    pieces
}

/// The last word of a path before any generic arguments: `windows::Win32::IFoo` is `IFoo`.
fn path_name(piece: &[Token]) -> Option<String> {
    piece
        .iter()
        .take_while(|t| !t.is_punct('<'))
        .filter_map(Token::word)
        .last()
        .map(str::to_owned)
}

// ---------------------------------------------------------------------------------------
// What the sources say
// ---------------------------------------------------------------------------------------

/// One `#[implement(...)]` object.
#[derive(Debug, Clone)]
struct Object {
    name: String,
    interfaces: Vec<String>,
    origin: String,
}

#[derive(Debug, Default)]
struct Source {
    objects: Vec<Object>,
    /// `#[interface("…")]` traits: name -> (IID, origin).
    iids: BTreeMap<String, (String, String)>,
}

/// Canonical lower-case `8-4-4-4-12` form of a GUID text; `None` if it is not one.
fn canonical_guid(text: &str) -> Option<String> {
    let t = text
        .trim()
        .trim_start_matches('{')
        .trim_end_matches('}')
        .to_ascii_lowercase();
    let parts: Vec<&str> = t.split('-').collect();
    let ok = parts.len() == 5
        && parts
            .iter()
            .zip([8, 4, 4, 4, 12])
            .all(|(p, n)| p.len() == n && p.chars().all(|c| c.is_ascii_hexdigit()));
    ok.then_some(t)
}

/// The objects and interface definitions of one file.
fn scan(src: &str, file: &str, out: &mut Source) {
    let toks = tokenize(src);
    let mut i = 0;
    let mut pending_iid: Option<String> = None;
    while i < toks.len() {
        if toks[i].is_punct('#') && toks.get(i + 1).is_some_and(|t| t.is_punct('[')) {
            let close = matching(&toks, i + 1);
            let attr = &toks[i + 2..close.min(toks.len())];
            let after = close + 1;
            // `#[cfg(test)] mod name { … }`: in-process test doubles, left out.
            if is_cfg_test(attr) {
                if let Some(open) = mod_block(&toks, after) {
                    i = matching(&toks, open) + 1;
                    continue;
                }
            }
            let paren = attr.iter().position(|t| t.is_punct('('));
            let head = attr[..paren.unwrap_or(attr.len())]
                .iter()
                .filter_map(Token::word)
                .next_back();
            if let (Some(p), Some("implement")) = (paren, head) {
                let end = matching(attr, p);
                let interfaces = split_commas(&attr[p + 1..end.min(attr.len())])
                    .into_iter()
                    .filter_map(path_name)
                    .collect();
                let name = toks[after..]
                    .windows(2)
                    .find(|w| w[0].is_word("struct"))
                    .and_then(|w| w[1].word())
                    .unwrap_or("?")
                    .to_owned();
                out.objects.push(Object {
                    name,
                    interfaces,
                    origin: format!("{file}:{}", toks[i].line),
                });
            }
            if let (Some(p), Some("interface")) = (paren, head) {
                pending_iid = attr.get(p + 1).and_then(|t| match &t.tok {
                    Tok::Str(s) => canonical_guid(s),
                    _ => None,
                });
            }
            i = after;
            continue;
        }
        if toks[i].is_word("trait") {
            if let (Some(iid), Some(name)) =
                (pending_iid.take(), toks.get(i + 1).and_then(Token::word))
            {
                let origin = format!("{file}:{}", toks[i].line);
                out.iids.insert(name.to_owned(), (iid, origin));
            }
        }
        i += 1;
    }
}

fn is_cfg_test(attr: &[Token]) -> bool {
    attr.len() == 4
        && attr[0].is_word("cfg")
        && attr[1].is_punct('(')
        && attr[2].is_word("test")
        && attr[3].is_punct(')')
}

/// At `toks[at]`, `[pub] mod name {`: the index of the `{`.
fn mod_block(toks: &[Token], at: usize) -> Option<usize> {
    let mut k = at;
    if toks.get(k).is_some_and(|t| t.is_word("pub")) {
        k += 1;
    }
    (toks.get(k)?.is_word("mod") && toks.get(k + 2)?.is_punct('{')).then_some(k + 2)
}

/// The interface names of `const LIST: &[GUID] = &[A::IID, b::B::IID, …];`, or why not.
fn iid_list(src: &str, list: &str) -> Result<Vec<String>, String> {
    let toks = tokenize(src);
    let at = toks
        .windows(2)
        .position(|w| w[0].is_word("const") && w[1].is_word(list))
        .ok_or(format!("no `const {list}`"))?;
    let eq = (at..toks.len())
        .find(|&k| toks[k].is_punct('='))
        .ok_or(format!("{list}: no `=`"))?;
    let open = (eq..toks.len())
        .find(|&k| toks[k].is_punct('['))
        .ok_or(format!("{list}: no `[`"))?;
    let close = matching(&toks, open);
    let mut names = Vec::new();
    for piece in split_commas(&toks[open + 1..close.min(toks.len())]) {
        let words: Vec<&str> = piece.iter().filter_map(Token::word).collect();
        match words.as_slice() {
            [.., name, "IID"] => names.push((*name).to_owned()),
            _ => {
                return Err(format!(
                "{list}: an entry this test does not understand (line {}): write it as `Name::IID`",
                piece[0].line
            ))
            }
        }
    }
    Ok(names)
}

// ---------------------------------------------------------------------------------------
// The check
// ---------------------------------------------------------------------------------------

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Role {
    Server,
    Client,
}

impl Role {
    fn list(self) -> &'static str {
        match self {
            Role::Server => "SERVER_IIDS",
            Role::Client => "CLIENT_IIDS",
        }
    }
}

/// Every interface of every object of `role` whose IID is not in `kept` (names of the
/// role's list), one line each; also names that resolve to no IID.
fn missing(
    objects: &[Object],
    role: Role,
    kept: &[String],
    iids: &BTreeMap<String, (String, String)>,
) -> Vec<String> {
    let mut problems = Vec::new();
    let resolve = |name: &str| -> Option<String> {
        iids.get(name).map(|(iid, _)| iid.clone()).or_else(|| {
            WINDOWS_IIDS
                .iter()
                .find(|(n, _)| *n == name)
                .map(|(_, iid)| (*iid).to_owned())
        })
    };
    let mut kept_iids = Vec::new();
    for name in kept {
        match resolve(name) {
            Some(iid) => kept_iids.push(iid),
            None => problems.push(format!(
                "{}: {name} has no known IID (no #[interface] trait of that name, not in WINDOWS_IIDS)",
                role.list()
            )),
        }
    }
    let implicit = Object {
        name: "every object".into(),
        interfaces: vec!["IUnknown".into()],
        origin: "#[implement]".into(),
    };
    for obj in objects.iter().chain(std::iter::once(&implicit)) {
        for itf in &obj.interfaces {
            if NOT_KEPT.iter().any(|(n, _)| n == itf) {
                continue;
            }
            match resolve(itf) {
                None => problems.push(format!(
                    "{itf} ({}, {}) has no known IID: add it to WINDOWS_IIDS in this test",
                    obj.name, obj.origin
                )),
                Some(iid) if !kept_iids.contains(&iid) => problems.push(format!(
                    "{itf} {{{iid}}} is implemented by {} ({}) but is not in {}: add `{itf}::IID` (or, with why, to NOT_KEPT in this test)",
                    obj.name,
                    obj.origin,
                    role.list()
                )),
                Some(_) => {}
            }
        }
    }
    problems
}

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("xtask has a parent")
        .to_path_buf()
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = fs::read_dir(dir) else {
        return;
    };
    let mut entries: Vec<PathBuf> = entries.flatten().map(|e| e.path()).collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|e| e == "rs") {
            out.push(p);
        }
    }
}

/// The role of a file's objects: the client library's sinks are a client's.
fn role_of(rel: &Path) -> Role {
    let client = rel.starts_with("crates/opc-client")
        || (rel.starts_with("crates/ctopc-com/src")
            && rel.components().any(|c| {
                let c = c.as_os_str().to_string_lossy();
                c == "client" || c == "client.rs"
            }));
    if client {
        Role::Client
    } else {
        Role::Server
    }
}

#[test]
fn the_keepalive_lists_cover_every_implemented_interface() {
    let root = root();
    let mut files = Vec::new();
    for dir in [
        "crates/ctopc-com/src",
        "crates/serverlist/src",
        "crates/opc-client/src",
    ] {
        rust_files(&root.join(dir), &mut files);
    }
    let mut server = Source::default();
    let mut client = Source::default();
    let mut lists_in = Vec::new();
    for f in &files {
        let rel = f.strip_prefix(&root).unwrap_or(f);
        let src = fs::read_to_string(f).unwrap_or_else(|e| panic!("read {}: {e}", f.display()));
        let into = match role_of(rel) {
            Role::Server => &mut server,
            Role::Client => &mut client,
        };
        scan(&src, &rel.display().to_string(), into);
        if rel.starts_with("crates/ctopc-com/src")
            && tokenize(&src)
                .windows(2)
                .any(|w| w[0].is_word("const") && w[1].is_word("SERVER_IIDS"))
        {
            lists_in.push((rel.to_path_buf(), src));
        }
    }
    assert_eq!(
        lists_in.len(),
        1,
        "exactly one file under crates/ctopc-com/src should define SERVER_IIDS: {:?}",
        lists_in.iter().map(|(p, _)| p).collect::<Vec<_>>()
    );
    let (list_file, list_src) = &lists_in[0];
    let server_list = iid_list(list_src, "SERVER_IIDS").unwrap();
    let client_list = iid_list(list_src, "CLIENT_IIDS").unwrap();

    let mut iids = server.iids.clone();
    iids.extend(client.iids.clone());
    // Guard against a scanner that silently finds nothing.
    assert!(
        server.objects.len() >= 10,
        "only {} server objects found",
        server.objects.len()
    );
    assert!(
        iids.len() >= 20,
        "only {} #[interface] traits found",
        iids.len()
    );
    assert!(server_list.len() >= 20, "SERVER_IIDS: {server_list:?}");

    let mut problems = missing(&server.objects, Role::Server, &server_list, &iids);
    problems.extend(missing(&client.objects, Role::Client, &client_list, &iids));
    assert!(
        problems.is_empty(),
        "the Wine keep-alive's lists ({}) miss interfaces our objects implement:\n  - {}",
        list_file.display(),
        problems.join("\n  - ")
    );
}

// ---------------------------------------------------------------------------------------
// Scanner unit tests
// ---------------------------------------------------------------------------------------

const SAMPLE: &str = r##"
use windows::Win32::System::Com::IConnectionPoint;
/// Not an object: #[implement(IFake)] in a doc comment.
#[interface("B196B286-BAB4-101A-B69C-00AA00341D07")]
pub unsafe trait RawConnectionPoint: IUnknown {}

#[interface("39c13a54-011e-11d0-9675-0020afd8adb3")]
pub unsafe trait IOPCItemMgt: IUnknown {}

#[windows_core::implement(
    IOPCItemMgt,
    RawConnectionPoint, // the standard one, redefined
)]
pub struct Group {
    x: u32,
}

const S: &str = "#[implement(INotInAString)] struct X;";
const C: char = '[';
/* #[implement(INotInABlock)] /* nested */ struct Y; */

#[implement(windows::Win32::System::Com::IEnumString)]
struct Strings<'a>(&'a str);

#[cfg(test)]
mod tests {
    #[implement(IOPCDataCallback)]
    struct TestSink;
}

pub const SERVER_IIDS: &[GUID] = &[
    IUnknown::IID,
    IOPCItemMgt::IID,
    windows::Win32::System::Com::IConnectionPoint::IID,
];
"##;

#[test]
fn the_scanner_reads_objects_interfaces_and_the_list() {
    let mut s = Source::default();
    scan(SAMPLE, "sample.rs", &mut s);
    let objects: Vec<(&str, Vec<&str>)> = s
        .objects
        .iter()
        .map(|o| {
            (
                o.name.as_str(),
                o.interfaces.iter().map(String::as_str).collect(),
            )
        })
        .collect();
    assert_eq!(
        objects,
        [
            ("Group", vec!["IOPCItemMgt", "RawConnectionPoint"]),
            ("Strings", vec!["IEnumString"]),
        ]
    );
    assert_eq!(s.objects[0].origin, "sample.rs:10");
    assert_eq!(
        s.iids["RawConnectionPoint"].0,
        "b196b286-bab4-101a-b69c-00aa00341d07"
    );
    assert_eq!(s.iids.len(), 2);
    assert_eq!(
        iid_list(SAMPLE, "SERVER_IIDS").unwrap(),
        ["IUnknown", "IOPCItemMgt", "IConnectionPoint"]
    );
    assert!(iid_list("const L: &[GUID] = &[GUID::zeroed()];", "L").is_err());
}

#[test]
fn an_interface_missing_from_the_list_is_reported_and_a_redefinition_counts_by_iid() {
    let mut s = Source::default();
    scan(SAMPLE, "sample.rs", &mut s);
    let list = iid_list(SAMPLE, "SERVER_IIDS").unwrap();
    let problems = missing(&s.objects, Role::Server, &list, &s.iids);
    // RawConnectionPoint is IConnectionPoint by IID; IEnumString is missing.
    assert_eq!(problems.len(), 1, "{problems:#?}");
    assert!(
        problems[0].starts_with(
            "IEnumString {00000101-0000-0000-c000-000000000046} is implemented by Strings (sample.rs:22) but is not in SERVER_IIDS"
        ),
        "{}",
        problems[0]
    );

    let without_unknown: Vec<String> = list.into_iter().filter(|n| n != "IUnknown").collect();
    let problems = missing(&[], Role::Client, &without_unknown, &s.iids);
    assert_eq!(problems.len(), 1, "{problems:#?}");
    assert!(
        problems[0].starts_with(
            "IUnknown {00000000-0000-0000-c000-000000000046} is implemented by every object"
        ),
        "{}",
        problems[0]
    );

    let unknown = Object {
        name: "X".into(),
        interfaces: vec!["IUnheardOf".into()],
        origin: "x.rs:1".into(),
    };
    let problems = missing(&[unknown], Role::Server, &["IUnknown".into()], &s.iids);
    assert_eq!(
        problems,
        ["IUnheardOf (X, x.rs:1) has no known IID: add it to WINDOWS_IIDS in this test"]
    );
}

#[test]
fn client_library_files_are_the_client_role() {
    assert_eq!(
        role_of(Path::new("crates/ctopc-com/src/client/diag.rs")),
        Role::Client
    );
    assert_eq!(
        role_of(Path::new("crates/ctopc-com/src/client.rs")),
        Role::Client
    );
    assert_eq!(
        role_of(Path::new("crates/opc-client/src/lib.rs")),
        Role::Client
    );
    assert_eq!(
        role_of(Path::new("crates/ctopc-com/src/group/mod.rs")),
        Role::Server
    );
    assert_eq!(
        role_of(Path::new("crates/serverlist/src/server_list.rs")),
        Role::Server
    );
}
