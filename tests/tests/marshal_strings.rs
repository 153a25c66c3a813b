//! String out-parameters across processes: every string an OPC interface hands out
//! (`[out]` and `[in, out]` string pointers, string arrays, string members of returned
//! structures) arrives at an out-of-process client non-NULL and intact, Polish diacritics
//! and UTF-16 surrogate pairs included, through the project's proxy/stub DLL `opc_ps.dll`.
//! This is the end-to-end check of widl bug 2 (shared docs, windows-on-linux.md: widl's
//! `-Oicf` type offsets of `[out] LPWSTR *` parameters make Wine deliver NULL strings;
//! `cargo xtask proxy` re-points them).
//!
//! The server is `marshal-probe.exe` (ProgID `ServerCTOPC.MarshalProbe`, crate e2e-tests,
//! objects in `e2e_tests::probe`): every string it returns is `"<parameter> – Wytwórnia
//! Kwasu żółć 🏭"` with the parameter named as in the table below (`[i]` appended for the
//! elements of arrays). The test registers it itself (`/RegServer`, once per run) and
//! connects with CLSCTX_LOCAL_SERVER; the proxy/stub DLL must be registered in the prefix
//! (`cargo xtask test` does that).
//!
//! `IDL_STRING_OUTPUTS` is the complete list of string outputs declared in `idl/*.idl`:
//! `table_lists_every_string_output_declared_in_idl` (native as well as under Wine)
//! derives the list from the IDL and fails when a row is missing or stale, and when a
//! named test does not exist in this file.

/// Every string output of every interface in `idl/` (`Interface::Method(param)`, then
/// `.member` through returned structures, as the IDL names them), with the tests that read
/// it back through the proxy.
const IDL_STRING_OUTPUTS: &[(&str, &[&str])] = &[
    // opccomn.idl
    (
        COMMON_GET_ERROR_STRING,
        &["iopccommon_geterrorstring_string_arrives_intact"],
    ),
    (
        LIST_PROGID,
        &["iopcserverlist_getclassdetails_progid_arrives_intact"],
    ),
    (
        LIST_USER_TYPE,
        &["iopcserverlist_getclassdetails_user_type_arrives_intact"],
    ),
    (
        LIST2_PROGID,
        &["iopcserverlist2_getclassdetails_progid_arrives_intact"],
    ),
    (
        LIST2_USER_TYPE,
        &["iopcserverlist2_getclassdetails_user_type_arrives_intact"],
    ),
    (
        LIST2_VER_IND_PROGID,
        &["iopcserverlist2_getclassdetails_ver_ind_progid_arrives_intact"],
    ),
    // opcda.idl
    (
        SERVER_GET_ERROR_STRING,
        &["iopcserver_geterrorstring_string_arrives_intact"],
    ),
    (
        SERVER_STATUS_VENDOR_INFO,
        &["iopcserver_getstatus_vendor_info_arrives_intact"],
    ),
    (
        BSAS_ITEM_ID,
        &["iopcbrowseserveraddressspace_getitemid_item_id_arrives_intact"],
    ),
    (
        GROUP_NAME,
        &[
            "iopcgroupstatemgt_getstate_name_arrives_intact",
            "iopcgroupstatemgt2_getstate_name_arrives_intact",
        ],
    ),
    (
        ITEM_ACCESS_PATH,
        &["ienumopcitemattributes_next_access_path_arrives_intact"],
    ),
    (
        ITEM_ITEM_ID,
        &["ienumopcitemattributes_next_item_id_arrives_intact"],
    ),
    (
        PROPS_DESCRIPTIONS,
        &["iopcitemproperties_queryavailableproperties_descriptions_arrive_intact"],
    ),
    (
        PROPS_NEW_ITEM_IDS,
        &["iopcitemproperties_lookupitemids_new_item_ids_arrive_intact"],
    ),
    (
        GET_PROPERTIES_ITEM_ID,
        &["iopcbrowse_getproperties_property_item_id_arrives_intact"],
    ),
    (
        GET_PROPERTIES_DESCRIPTION,
        &["iopcbrowse_getproperties_property_description_arrives_intact"],
    ),
    (
        BROWSE_CONTINUATION_POINT,
        &[
            "iopcbrowse_browse_continuation_point_arrives_intact",
            "iopcbrowse_browse_continuation_point_returns_to_the_server_intact",
        ],
    ),
    (
        BROWSE_NAME,
        &["iopcbrowse_browse_element_name_arrives_intact"],
    ),
    (
        BROWSE_ITEM_ID,
        &["iopcbrowse_browse_element_item_id_arrives_intact"],
    ),
    (
        BROWSE_PROPERTY_ITEM_ID,
        &["iopcbrowse_browse_element_property_item_id_arrives_intact"],
    ),
    (
        BROWSE_PROPERTY_DESCRIPTION,
        &["iopcbrowse_browse_element_property_description_arrives_intact"],
    ),
];

/// Strings that reach the client through an interface an OPC method returns rather than
/// through an IDL string parameter: IEnumString, marshalled by the system's proxy (ole32),
/// not by opc_ps.dll. Covered too, for completeness.
const ENUM_STRING_OUTPUTS: &[(&str, &[&str])] = &[
    (
        SERVER_GROUP_NAMES,
        &["iopcserver_creategroupenumerator_group_names_arrive_intact"],
    ),
    (
        BSAS_ITEM_IDS,
        &["iopcbrowseserveraddressspace_browseopcitemids_item_ids_arrive_intact"],
    ),
    (
        BSAS_ACCESS_PATHS,
        &["iopcbrowseserveraddressspace_browseaccesspaths_access_paths_arrive_intact"],
    ),
];

const COMMON_GET_ERROR_STRING: &str = "IOPCCommon::GetErrorString(ppString)";
const LIST_PROGID: &str = "IOPCServerList::GetClassDetails(ppszProgID)";
const LIST_USER_TYPE: &str = "IOPCServerList::GetClassDetails(ppszUserType)";
const LIST2_PROGID: &str = "IOPCServerList2::GetClassDetails(ppszProgID)";
const LIST2_USER_TYPE: &str = "IOPCServerList2::GetClassDetails(ppszUserType)";
const LIST2_VER_IND_PROGID: &str = "IOPCServerList2::GetClassDetails(ppszVerIndProgID)";
const SERVER_GET_ERROR_STRING: &str = "IOPCServer::GetErrorString(ppString)";
const SERVER_STATUS_VENDOR_INFO: &str = "IOPCServer::GetStatus(ppServerStatus).szVendorInfo";
const BSAS_ITEM_ID: &str = "IOPCBrowseServerAddressSpace::GetItemID(szItemID)";
const GROUP_NAME: &str = "IOPCGroupStateMgt::GetState(ppName)";
const ITEM_ACCESS_PATH: &str = "IEnumOPCItemAttributes::Next(ppItemArray).szAccessPath";
const ITEM_ITEM_ID: &str = "IEnumOPCItemAttributes::Next(ppItemArray).szItemID";
const PROPS_DESCRIPTIONS: &str = "IOPCItemProperties::QueryAvailableProperties(ppDescriptions)";
const PROPS_NEW_ITEM_IDS: &str = "IOPCItemProperties::LookupItemIDs(ppszNewItemIDs)";
const GET_PROPERTIES_ITEM_ID: &str =
    "IOPCBrowse::GetProperties(ppItemProperties).pItemProperties.szItemID";
const GET_PROPERTIES_DESCRIPTION: &str =
    "IOPCBrowse::GetProperties(ppItemProperties).pItemProperties.szDescription";
const BROWSE_CONTINUATION_POINT: &str = "IOPCBrowse::Browse(pszContinuationPoint)";
const BROWSE_NAME: &str = "IOPCBrowse::Browse(ppBrowseElements).szName";
const BROWSE_ITEM_ID: &str = "IOPCBrowse::Browse(ppBrowseElements).szItemID";
const BROWSE_PROPERTY_ITEM_ID: &str =
    "IOPCBrowse::Browse(ppBrowseElements).ItemProperties.pItemProperties.szItemID";
const BROWSE_PROPERTY_DESCRIPTION: &str =
    "IOPCBrowse::Browse(ppBrowseElements).ItemProperties.pItemProperties.szDescription";
const SERVER_GROUP_NAMES: &str =
    "IOPCServer::CreateGroupEnumerator(ppUnk)->IEnumString::Next(rgelt)";
const BSAS_ITEM_IDS: &str =
    "IOPCBrowseServerAddressSpace::BrowseOPCItemIDs(ppIEnumString)->IEnumString::Next(rgelt)";
const BSAS_ACCESS_PATHS: &str =
    "IOPCBrowseServerAddressSpace::BrowseAccessPaths(ppIEnumString)->IEnumString::Next(rgelt)";

/// What the probe returns in the string named `param` (stated here independently of
/// `e2e_tests::probe::text`, so that the test pins the exact text).
fn expected(param: &str) -> String {
    format!("{param} – Wytwórnia Kwasu żółć 🏭")
}

#[cfg_attr(not(windows), allow(dead_code))]
fn expected_at(param: &str, i: usize) -> String {
    expected(&format!("{param}[{i}]"))
}

#[cfg_attr(not(windows), allow(dead_code))]
fn expected_at2(param: &str, i: usize, j: usize) -> String {
    expected(&format!("{param}[{i}][{j}]"))
}

#[test]
fn expected_texts_contain_polish_diacritics_and_a_surrogate_pair() {
    let t = expected(COMMON_GET_ERROR_STRING);
    assert!(
        t.contains('ż') && t.contains('ó') && t.contains('ł') && t.contains('ć'),
        "{t}"
    );
    let units: Vec<u16> = t.encode_utf16().collect();
    assert!(
        units.windows(2).any(|w| w == [0xD83C, 0xDFED]),
        "U+1F3ED as a surrogate pair"
    );
    assert_eq!(
        t.chars().count() + 1,
        units.len(),
        "exactly one character outside the BMP"
    );
}

// ---------------------------------------------------------------------------------------
// The table against idl/*.idl
// ---------------------------------------------------------------------------------------

/// A small reader of the project's IDL (std only, so that it runs natively too): the
/// strings reachable from every `[out]` / `[in, out]` parameter.
mod idl {
    use std::collections::{BTreeMap, BTreeSet};

    /// Pointer-to-string typedefs (a parameter or member of one of these types is a string).
    const STRING_TYPES: &[&str] = &[
        "LPWSTR",
        "LPCWSTR",
        "LPOLESTR",
        "LPCOLESTR",
        "LPSTR",
        "LPCSTR",
        "BSTR",
    ];

    /// A declaration `[attrs] TYPE *...* name`.
    #[derive(Debug)]
    struct Decl {
        attrs: Vec<String>,
        base: String,
        name: String,
    }

    impl Decl {
        fn is_string(&self) -> bool {
            STRING_TYPES.contains(&self.base.as_str()) || self.attrs.iter().any(|a| a == "string")
        }
    }

    /// The text without comments and without the contents of string literals.
    fn strip(src: &str) -> String {
        let mut out = String::with_capacity(src.len());
        let mut chars = src.chars().peekable();
        while let Some(c) = chars.next() {
            match (c, chars.peek()) {
                ('/', Some('/')) => {
                    for c in chars.by_ref() {
                        if c == '\n' {
                            out.push('\n');
                            break;
                        }
                    }
                }
                ('/', Some('*')) => {
                    chars.next();
                    let mut prev = ' ';
                    for c in chars.by_ref() {
                        if prev == '*' && c == '/' {
                            break;
                        }
                        prev = c;
                    }
                    out.push(' ');
                }
                ('"', _) => {
                    let mut escaped = false;
                    for c in chars.by_ref() {
                        if c == '"' && !escaped {
                            break;
                        }
                        escaped = c == '\\' && !escaped;
                    }
                    out.push_str("\"\"");
                }
                _ => out.push(c),
            }
        }
        out
    }

    /// Splits at `sep` outside (), [] and {}.
    fn split_top(s: &str, sep: char) -> Vec<&str> {
        let mut parts = Vec::new();
        let (mut depth, mut start) = (0i32, 0);
        for (i, c) in s.char_indices() {
            match c {
                '(' | '[' | '{' => depth += 1,
                ')' | ']' | '}' => depth -= 1,
                c if c == sep && depth == 0 => {
                    parts.push(&s[start..i]);
                    start = i + c.len_utf8();
                }
                _ => {}
            }
        }
        parts.push(&s[start..]);
        parts
    }

    /// The index just after the bracket matching the one at `open`.
    fn matching(s: &str, open: usize) -> Option<usize> {
        let mut depth = 0i32;
        for (i, c) in s[open..].char_indices() {
            match c {
                '(' | '[' | '{' => depth += 1,
                ')' | ']' | '}' => {
                    depth -= 1;
                    if depth == 0 {
                        return Some(open + i + 1);
                    }
                }
                _ => {}
            }
        }
        None
    }

    fn idents(s: &str) -> Vec<&str> {
        s.split(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
            .filter(|t| !t.is_empty())
            .collect()
    }

    /// Whole-word occurrences of `word`.
    fn find_words<'a>(s: &'a str, word: &'a str) -> impl Iterator<Item = usize> + 'a {
        let ident = |c: char| c.is_ascii_alphanumeric() || c == '_';
        s.match_indices(word).map(|(i, _)| i).filter(move |&i| {
            !s[..i].chars().next_back().is_some_and(ident)
                && !s[i + word.len()..].chars().next().is_some_and(ident)
        })
    }

    fn parse_decl(d: &str) -> Option<Decl> {
        let d = d.trim();
        if d.is_empty() || d == "void" {
            return None;
        }
        let (attrs, rest) = match d.strip_prefix('[') {
            Some(_) => {
                let end = matching(d, 0)?;
                (&d[1..end - 1], &d[end..])
            }
            None => ("", d),
        };
        let attrs = split_top(attrs, ',')
            .into_iter()
            .filter_map(|a| idents(a).first().map(|s| s.to_string()))
            .collect();
        // `name[]` / `name[128]`: drop the array suffix.
        let rest = rest.split('[').next().unwrap_or(rest);
        let words: Vec<&str> = idents(rest)
            .into_iter()
            .filter(|w| !matches!(*w, "const" | "struct" | "unsigned" | "signed"))
            .collect();
        let (name, base) = (words.last()?, words.first()?);
        if words.len() < 2 {
            return None;
        }
        Some(Decl {
            attrs,
            base: base.to_string(),
            name: name.to_string(),
        })
    }

    /// `typedef struct tag { members } NAME;` -> NAME -> members.
    fn structs(text: &str) -> BTreeMap<String, Vec<Decl>> {
        let mut out = BTreeMap::new();
        for at in find_words(text, "struct") {
            let Some(open) = text[at..].find('{').map(|i| at + i) else {
                continue;
            };
            if text[at + "struct".len()..open].contains(';') {
                continue; // a forward declaration or a `struct X*` member
            }
            let Some(close) = matching(text, open) else {
                continue;
            };
            let Some(semi) = text[close..].find(';') else {
                continue;
            };
            let Some(name) = idents(&text[close..close + semi])
                .last()
                .map(|s| s.to_string())
            else {
                continue;
            };
            let members = text[open + 1..close - 1]
                .split(';')
                .filter_map(parse_decl)
                .collect();
            out.insert(name, members);
        }
        out
    }

    /// The string paths inside structure `ty` (`member` or `member.inner...`).
    fn string_members(
        structs: &BTreeMap<String, Vec<Decl>>,
        ty: &str,
        depth: usize,
    ) -> Vec<String> {
        let Some(members) = structs.get(ty).filter(|_| depth < 8) else {
            return Vec::new();
        };
        let mut out = Vec::new();
        for m in members {
            if m.is_string() {
                out.push(m.name.clone());
            } else {
                out.extend(
                    string_members(structs, &m.base, depth + 1)
                        .into_iter()
                        .map(|p| format!("{}.{p}", m.name)),
                );
            }
        }
        out
    }

    /// Every string output of every interface method declared in `sources`.
    pub fn string_outputs(sources: &[&str]) -> BTreeSet<String> {
        let text: String = sources
            .iter()
            .map(|s| strip(s))
            .collect::<Vec<_>>()
            .join("\n");
        let structs = structs(&text);
        let mut out = BTreeSet::new();
        for at in find_words(&text, "interface") {
            let after = &text[at + "interface".len()..];
            let Some(name) = idents(after).first().map(|s| s.to_string()) else {
                continue;
            };
            let Some(open) = after.find(['{', ';']) else {
                continue;
            };
            if after.as_bytes()[open] == b';' {
                continue; // forward declaration
            }
            let Some(close) = matching(after, open) else {
                continue;
            };
            for decl in split_top(&after[open + 1..close - 1], ';') {
                let decl = decl.trim();
                if decl.is_empty() || decl.starts_with("typedef") || decl.starts_with("const") {
                    continue;
                }
                let (Some(lp), Some(rp)) = (decl.find('('), decl.rfind(')')) else {
                    continue;
                };
                let Some(method) = idents(&decl[..lp]).last().map(|s| s.to_string()) else {
                    continue;
                };
                for p in split_top(&decl[lp + 1..rp], ',')
                    .into_iter()
                    .filter_map(parse_decl)
                {
                    if !p.attrs.iter().any(|a| a == "out") {
                        continue;
                    }
                    let at = format!("{name}::{method}({})", p.name);
                    if p.is_string() {
                        out.insert(at);
                    } else {
                        out.extend(
                            string_members(&structs, &p.base, 0)
                                .into_iter()
                                .map(|m| format!("{at}.{m}")),
                        );
                    }
                }
            }
        }
        out
    }
}

#[test]
fn table_lists_every_string_output_declared_in_idl() {
    use std::collections::BTreeSet;
    let declared = idl::string_outputs(&[
        include_str!("../../idl/opccomn.idl"),
        include_str!("../../idl/opcda.idl"),
    ]);
    // The reader itself must see the well-known ones, else the comparison proves nothing.
    for known in [
        COMMON_GET_ERROR_STRING,
        SERVER_STATUS_VENDOR_INFO,
        BROWSE_CONTINUATION_POINT,
        BROWSE_PROPERTY_DESCRIPTION,
    ] {
        assert!(
            declared.contains(known),
            "the IDL reader missed {known}: {declared:#?}"
        );
    }
    let listed: BTreeSet<String> = IDL_STRING_OUTPUTS
        .iter()
        .map(|(p, _)| p.to_string())
        .collect();
    assert_eq!(
        listed.len(),
        IDL_STRING_OUTPUTS.len(),
        "a row is listed twice"
    );
    let missing: Vec<_> = declared.difference(&listed).collect();
    let stale: Vec<_> = listed.difference(&declared).collect();
    assert!(
        missing.is_empty() && stale.is_empty(),
        "string outputs declared in idl/ without a row (add a probe output and a test): {missing:#?}\n\
         rows not declared in idl/: {stale:#?}"
    );
    let source = include_str!("marshal_strings.rs");
    for (param, tests) in IDL_STRING_OUTPUTS.iter().chain(ENUM_STRING_OUTPUTS) {
        assert!(!tests.is_empty(), "{param}: no test");
        for t in *tests {
            assert!(
                source.contains(&format!("fn {t}()")),
                "{param}: the table names test `{t}`, which does not exist"
            );
        }
    }
}

// ---------------------------------------------------------------------------------------
// Through the proxy (Windows / Wine only)
// ---------------------------------------------------------------------------------------

#[cfg(windows)]
mod through_the_proxy {
    use super::*;
    use ctopc_com::apartment::Apartment;
    use e2e_tests::probe::{self, client as read};
    use e2e_tests::start::StartRetrying;
    use e2e_tests::{artifact, code, interfaces::*};
    use opc_client::{BrowseArgs, BrowseElement, BrowsePage, Server};
    use std::process::Command;
    use std::sync::OnceLock;
    use std::time::{Duration, Instant};
    use windows::core::{Interface, GUID, HRESULT};
    use windows::Win32::Foundation::{S_FALSE, S_OK};
    use windows::Win32::System::Com::IClientSecurity;

    /// A string that should have arrived: non-NULL and exactly `want`.
    #[track_caller]
    fn assert_intact(what: &str, got: Option<&str>, want: &str) {
        match got {
            None => panic!(
                "{what}: arrived NULL at the out-of-process client (sent: {want:?}); the proxy/stub \
                 DLL does not marshal this string back (widl bug 2 not fixed for it?)"
            ),
            Some(got) => assert_eq!(got, want, "{what}: arrived altered"),
        }
    }

    /// Runs `marshal-probe.exe /RegServer` (the 64-bit one, as the server is: a 32-bit run
    /// of this suite tests the 32-bit proxy against the 64-bit stub) once per test run.
    fn register_probe() -> Result<(), String> {
        let exe = artifact("marshal-probe.exe");
        let mut child = Command::new(&exe)
            .arg("/RegServer")
            .spawn_retrying()
            .map_err(|e| format!("{}: {e}", exe.display()))?;
        let deadline = Instant::now() + Duration::from_secs(60);
        loop {
            if let Some(status) = child.try_wait().map_err(|e| e.to_string())? {
                return if status.success() {
                    Ok(())
                } else {
                    Err(format!("{} /RegServer: {status}", exe.display()))
                };
            }
            if Instant::now() > deadline {
                let _ = child.kill();
                return Err(format!(
                    "{} /RegServer did not finish within 60 s",
                    exe.display()
                ));
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    static REGISTERED: OnceLock<Result<(), String>> = OnceLock::new();

    /// Joins the MTA and creates a probe server object in the probe's own process.
    fn connect() -> (Apartment, Server) {
        let com = Apartment::mta().expect("CoInitializeEx");
        if let Err(e) = REGISTERED.get_or_init(register_probe) {
            panic!("registering the marshal probe: {e}");
        }
        let server = Server::connect(probe::PROGID)
            .expect("CoCreateInstance(ServerCTOPC.MarshalProbe, CLSCTX_LOCAL_SERVER)");
        (com, server)
    }

    fn group(server: &Server, riid: &GUID) -> windows::core::IUnknown {
        read::add_group(&server.server, "grupa", riid).expect("AddGroup")
    }

    /// `IOPCBrowse::Browse` of the root with `continuation_point` as the [in, out]
    /// parameter's input (a CoTaskMem copy the server frees), all properties when
    /// `all_properties`. A failed call is `Err`.
    fn browse_root(
        server: &Server,
        continuation_point: Option<&str>,
        all_properties: bool,
    ) -> windows::core::Result<BrowsePage> {
        server.browse(&BrowseArgs {
            continuation_point: continuation_point.map(String::from),
            all_properties,
            ..BrowseArgs::all("")
        })
    }

    /// Every element of the root, page by page, following the continuation points.
    fn browse_all(server: &Server, all_properties: bool) -> Vec<BrowseElement> {
        let mut elements = Vec::new();
        let mut cp: Option<String> = None;
        for _ in 0..10 {
            let page = browse_root(server, cp.as_deref(), all_properties).expect("Browse");
            elements.extend(page.elements);
            if !page.more_elements {
                return elements;
            }
            cp = Some(
                page.continuation_point
                    .expect("a continuation point with more elements"),
            );
        }
        panic!("Browse does not end");
    }

    #[test]
    fn the_probe_is_reached_through_a_proxy() {
        let (_com, server) = connect();
        // IClientSecurity is implemented by the COM proxy manager, never by the probe object:
        // the objects live in marshal-probe.exe and every call below crosses processes.
        assert!(
            server.unknown.cast::<IClientSecurity>().is_ok(),
            "not a proxy: the probe runs in this process?"
        );
        for iid in [
            IOPCServerList::IID,
            IOPCServerList2::IID,
            IOPCBrowseServerAddressSpace::IID,
            IOPCItemProperties::IID,
            IOPCBrowse::IID,
        ] {
            let mut out = std::ptr::null_mut();
            // SAFETY: valid IID and out-pointer; the reference is released below.
            let hr = unsafe { server.unknown.query(&iid, &mut out) };
            assert_eq!(hr, S_OK, "QueryInterface({iid:?})");
            // SAFETY: `out` holds the reference QueryInterface added.
            drop(unsafe { windows::core::IUnknown::from_raw(out) });
        }
    }

    // --- opccomn.idl -------------------------------------------------------------------

    #[test]
    fn iopccommon_geterrorstring_string_arrives_intact() {
        let (_com, server) = connect();
        let s = server
            .error_string(HRESULT(OPC_E_INVALIDHANDLE.0))
            .expect("IOPCCommon::GetErrorString");
        assert_intact(
            COMMON_GET_ERROR_STRING,
            s.as_deref(),
            &expected(COMMON_GET_ERROR_STRING),
        );
    }

    #[test]
    fn iopcserverlist_getclassdetails_progid_arrives_intact() {
        let (_com, server) = connect();
        let list = server
            .unknown
            .cast::<IOPCServerList>()
            .expect("IOPCServerList");
        let (progid, _) =
            read::class_details(&list, &probe::CLSID_MARSHAL_PROBE).expect("GetClassDetails");
        assert_intact(LIST_PROGID, progid.as_deref(), &expected(LIST_PROGID));
    }

    #[test]
    fn iopcserverlist_getclassdetails_user_type_arrives_intact() {
        let (_com, server) = connect();
        let list = server
            .unknown
            .cast::<IOPCServerList>()
            .expect("IOPCServerList");
        let (_, user_type) =
            read::class_details(&list, &probe::CLSID_MARSHAL_PROBE).expect("GetClassDetails");
        assert_intact(
            LIST_USER_TYPE,
            user_type.as_deref(),
            &expected(LIST_USER_TYPE),
        );
    }

    #[test]
    fn iopcserverlist2_getclassdetails_progid_arrives_intact() {
        let (_com, server) = connect();
        let list = server
            .unknown
            .cast::<IOPCServerList2>()
            .expect("IOPCServerList2");
        let (progid, _, _) =
            read::class_details2(&list, &probe::CLSID_MARSHAL_PROBE).expect("GetClassDetails");
        assert_intact(LIST2_PROGID, progid.as_deref(), &expected(LIST2_PROGID));
    }

    #[test]
    fn iopcserverlist2_getclassdetails_user_type_arrives_intact() {
        let (_com, server) = connect();
        let list = server
            .unknown
            .cast::<IOPCServerList2>()
            .expect("IOPCServerList2");
        let (_, user_type, _) =
            read::class_details2(&list, &probe::CLSID_MARSHAL_PROBE).expect("GetClassDetails");
        assert_intact(
            LIST2_USER_TYPE,
            user_type.as_deref(),
            &expected(LIST2_USER_TYPE),
        );
    }

    #[test]
    fn iopcserverlist2_getclassdetails_ver_ind_progid_arrives_intact() {
        let (_com, server) = connect();
        let list = server
            .unknown
            .cast::<IOPCServerList2>()
            .expect("IOPCServerList2");
        let (_, _, ver_ind) =
            read::class_details2(&list, &probe::CLSID_MARSHAL_PROBE).expect("GetClassDetails");
        assert_intact(
            LIST2_VER_IND_PROGID,
            ver_ind.as_deref(),
            &expected(LIST2_VER_IND_PROGID),
        );
    }

    // --- opcda.idl: server object ------------------------------------------------------

    #[test]
    fn iopcserver_geterrorstring_string_arrives_intact() {
        let (_com, server) = connect();
        let s = server
            .error_string_in(HRESULT(OPC_E_UNKNOWNITEMID.0), 0x0415)
            .expect("IOPCServer::GetErrorString");
        assert_intact(
            SERVER_GET_ERROR_STRING,
            s.as_deref(),
            &expected(SERVER_GET_ERROR_STRING),
        );
    }

    #[test]
    fn iopcserver_getstatus_vendor_info_arrives_intact() {
        let (_com, server) = connect();
        let status = server.status().expect("GetStatus");
        assert_intact(
            SERVER_STATUS_VENDOR_INFO,
            status.vendor_info.as_deref(),
            &expected(SERVER_STATUS_VENDOR_INFO),
        );
        // The members around the string kept their values.
        assert_eq!(status.state, OPC_STATUS_TEST.0 as u32);
        assert_eq!(status.band_width, u32::MAX);
    }

    #[test]
    fn iopcbrowseserveraddressspace_getitemid_item_id_arrives_intact() {
        let (_com, server) = connect();
        let id = server.get_item_id("Wydział/Pompa").expect("GetItemID");
        assert_intact(BSAS_ITEM_ID, id.as_deref(), &expected(BSAS_ITEM_ID));
    }

    #[test]
    fn iopcitemproperties_queryavailableproperties_descriptions_arrive_intact() {
        let (_com, server) = connect();
        let got = server
            .query_available_properties("Pompa.Ciśnienie")
            .expect("QueryAvailableProperties");
        assert_eq!(got.len(), probe::AVAILABLE_PROPERTIES.len());
        for (i, (id, description, _vt)) in got.iter().enumerate() {
            assert_eq!(*id, probe::AVAILABLE_PROPERTIES[i]);
            assert_intact(
                &format!("{PROPS_DESCRIPTIONS}[{i}]"),
                description.as_deref(),
                &expected_at(PROPS_DESCRIPTIONS, i),
            );
        }
    }

    #[test]
    fn iopcitemproperties_lookupitemids_new_item_ids_arrive_intact() {
        let (_com, server) = connect();
        let ids = [OPC_PROPERTY_EU_UNITS, OPC_PROPERTY_DESCRIPTION];
        let (hr, got) = server
            .lookup_item_ids("Pompa.Ciśnienie", &ids)
            .expect("LookupItemIDs");
        assert_eq!(hr, S_OK);
        for (i, (id, err)) in got.iter().enumerate() {
            assert_eq!(*err, S_OK);
            assert_intact(
                &format!("{PROPS_NEW_ITEM_IDS}[{i}]"),
                id.as_deref(),
                &expected_at(PROPS_NEW_ITEM_IDS, i),
            );
        }
        // A failed element (NULL, OPC_E_INVALID_PID) between two good ones: the good ones
        // still arrive, the failed one stays NULL.
        let ids = [
            OPC_PROPERTY_EU_UNITS,
            OPC_PROPERTY_VALUE,
            OPC_PROPERTY_DESCRIPTION,
        ];
        let (hr, got) = server
            .lookup_item_ids("Pompa.Ciśnienie", &ids)
            .expect("LookupItemIDs");
        assert_eq!(hr, S_FALSE);
        assert_eq!(got[1], (None, HRESULT(OPC_E_INVALID_PID.0)));
        for i in [0, 2] {
            assert_eq!(got[i].1, S_OK);
            assert_intact(
                &format!("{PROPS_NEW_ITEM_IDS}[{i}]"),
                got[i].0.as_deref(),
                &expected_at(PROPS_NEW_ITEM_IDS, i),
            );
        }
    }

    #[test]
    fn iopcbrowse_getproperties_property_item_id_arrives_intact() {
        let (_com, server) = connect();
        let (hr, items) = server
            .get_properties(&["Pompa.Ciśnienie", "Pompa.Prędkość"], false, &[])
            .expect("GetProperties");
        assert_eq!(hr, S_OK);
        assert_eq!(items.len(), 2);
        for (i, item) in items.iter().enumerate() {
            assert_eq!(item.properties.len(), probe::ALL_PROPERTIES.len());
            for (j, p) in item.properties.iter().enumerate() {
                let what = format!("{GET_PROPERTIES_ITEM_ID}[{i}][{j}]");
                assert_intact(
                    &what,
                    p.item_id.as_deref(),
                    &expected_at2(GET_PROPERTIES_ITEM_ID, i, j),
                );
            }
        }
    }

    #[test]
    fn iopcbrowse_getproperties_property_description_arrives_intact() {
        let (_com, server) = connect();
        let ids = [
            OPC_PROPERTY_EU_UNITS,
            OPC_PROPERTY_DESCRIPTION,
            OPC_PROPERTY_HIGH_EU,
        ];
        let (_, items) = server
            .get_properties(&["Pompa.Ciśnienie"], false, &ids)
            .expect("GetProperties");
        assert_eq!(items.len(), 1);
        let props = &items[0].properties;
        assert_eq!(props.iter().map(|p| p.id).collect::<Vec<_>>(), ids);
        for (j, p) in props.iter().enumerate() {
            let what = format!("{GET_PROPERTIES_DESCRIPTION}[0][{j}]");
            assert_intact(
                &what,
                p.description.as_deref(),
                &expected_at2(GET_PROPERTIES_DESCRIPTION, 0, j),
            );
        }
    }

    #[test]
    fn iopcbrowse_browse_continuation_point_arrives_intact() {
        let (_com, server) = connect();
        let page = browse_root(&server, None, false).expect("Browse");
        assert!(page.more_elements);
        assert_intact(
            BROWSE_CONTINUATION_POINT,
            page.continuation_point.as_deref(),
            &expected(BROWSE_CONTINUATION_POINT),
        );
    }

    #[test]
    fn iopcbrowse_browse_continuation_point_returns_to_the_server_intact() {
        let (_com, server) = connect();
        // [in] direction of the [in, out] parameter: the probe accepts only its own
        // continuation point, character for character...
        let page = browse_root(&server, Some(&expected(BROWSE_CONTINUATION_POINT)), false)
            .expect("Browse with the continuation point: the server did not receive it intact");
        assert_eq!(
            page.elements.len(),
            probe::BROWSE_ELEMENTS - probe::BROWSE_PAGE
        );
        assert!(!page.more_elements);
        assert_eq!(
            page.continuation_point, None,
            "no continuation point after the last page"
        );
        // ...and rejects any other.
        let bad = browse_root(
            &server,
            Some("IOPCBrowse::Browse(pszContinuationPoint) – Wytwórnia Kwasu zolc"),
            false,
        );
        assert_eq!(code(&bad), HRESULT(OPC_E_INVALIDCONTINUATIONPOINT.0));
    }

    #[test]
    fn iopcbrowse_browse_element_name_arrives_intact() {
        let (_com, server) = connect();
        let elements = browse_all(&server, false);
        assert_eq!(elements.len(), probe::BROWSE_ELEMENTS);
        for (k, e) in elements.iter().enumerate() {
            assert_intact(
                &format!("{BROWSE_NAME}[{k}]"),
                e.name.as_deref(),
                &expected_at(BROWSE_NAME, k),
            );
            assert!(e.properties.properties.is_empty());
        }
    }

    #[test]
    fn iopcbrowse_browse_element_item_id_arrives_intact() {
        let (_com, server) = connect();
        let elements = browse_all(&server, false);
        assert_eq!(elements.len(), probe::BROWSE_ELEMENTS);
        for (k, e) in elements.iter().enumerate() {
            assert_intact(
                &format!("{BROWSE_ITEM_ID}[{k}]"),
                e.item_id.as_deref(),
                &expected_at(BROWSE_ITEM_ID, k),
            );
            assert_eq!(e.flags, OPC_BROWSE_ISITEM);
        }
    }

    #[test]
    fn iopcbrowse_browse_element_property_item_id_arrives_intact() {
        let (_com, server) = connect();
        let elements = browse_all(&server, true);
        assert_eq!(elements.len(), probe::BROWSE_ELEMENTS);
        for (k, e) in elements.iter().enumerate() {
            assert_intact(
                &format!("{BROWSE_NAME}[{k}]"),
                e.name.as_deref(),
                &expected_at(BROWSE_NAME, k),
            );
            assert_eq!(e.properties.properties.len(), probe::ALL_PROPERTIES.len());
            for (j, p) in e.properties.properties.iter().enumerate() {
                let what = format!("{BROWSE_PROPERTY_ITEM_ID}[{k}][{j}]");
                assert_intact(
                    &what,
                    p.item_id.as_deref(),
                    &expected_at2(BROWSE_PROPERTY_ITEM_ID, k, j),
                );
            }
        }
    }

    #[test]
    fn iopcbrowse_browse_element_property_description_arrives_intact() {
        let (_com, server) = connect();
        let elements = browse_all(&server, true);
        assert_eq!(elements.len(), probe::BROWSE_ELEMENTS);
        for (k, e) in elements.iter().enumerate() {
            assert_eq!(e.properties.properties.len(), probe::ALL_PROPERTIES.len());
            for (j, p) in e.properties.properties.iter().enumerate() {
                let what = format!("{BROWSE_PROPERTY_DESCRIPTION}[{k}][{j}]");
                assert_intact(
                    &what,
                    p.description.as_deref(),
                    &expected_at2(BROWSE_PROPERTY_DESCRIPTION, k, j),
                );
            }
        }
    }

    // --- opcda.idl: group object -------------------------------------------------------

    #[test]
    fn iopcgroupstatemgt_getstate_name_arrives_intact() {
        let (_com, server) = connect();
        let g = group(&server, &IOPCGroupStateMgt::IID)
            .cast::<IOPCGroupStateMgt>()
            .expect("IOPCGroupStateMgt");
        let (name, rate, client, server_handle) = read::group_state_name(&g).expect("GetState");
        assert_intact(GROUP_NAME, name.as_deref(), &expected(GROUP_NAME));
        // The out-parameters after ppName kept their values.
        assert_eq!(
            (rate, client, server_handle),
            (
                probe::GROUP_UPDATE_RATE,
                probe::GROUP_CLIENT_HANDLE,
                probe::GROUP_SERVER_HANDLE
            )
        );
    }

    #[test]
    fn iopcgroupstatemgt2_getstate_name_arrives_intact() {
        let (_com, server) = connect();
        // GetState called through the IOPCGroupStateMgt2 proxy (its inherited method).
        let g2 = group(&server, &IOPCGroupStateMgt2::IID)
            .cast::<IOPCGroupStateMgt2>()
            .expect("IOPCGroupStateMgt2");
        let (name, rate, _, _) = read::group_state_name(&g2).expect("GetState");
        assert_intact(GROUP_NAME, name.as_deref(), &expected(GROUP_NAME));
        assert_eq!(rate, probe::GROUP_UPDATE_RATE);
    }

    #[test]
    fn ienumopcitemattributes_next_access_path_arrives_intact() {
        let (_com, server) = connect();
        let items = group(&server, &IOPCItemMgt::IID)
            .cast::<IOPCItemMgt>()
            .expect("IOPCItemMgt");
        // One element per Next call.
        let got = read::item_attributes(&items, 1).expect("IEnumOPCItemAttributes::Next");
        assert_eq!(got.len(), probe::ITEM_COUNT);
        for (k, a) in got.iter().enumerate() {
            assert_intact(
                &format!("{ITEM_ACCESS_PATH}[{k}]"),
                a.access_path.as_deref(),
                &expected_at(ITEM_ACCESS_PATH, k),
            );
        }
    }

    #[test]
    fn ienumopcitemattributes_next_item_id_arrives_intact() {
        let (_com, server) = connect();
        let items = group(&server, &IOPCItemMgt::IID)
            .cast::<IOPCItemMgt>()
            .expect("IOPCItemMgt");
        // All elements in one Next call (S_FALSE: fewer than asked for).
        let got = read::item_attributes(&items, 10).expect("IEnumOPCItemAttributes::Next");
        assert_eq!(got.len(), probe::ITEM_COUNT);
        for (k, a) in got.iter().enumerate() {
            assert_intact(
                &format!("{ITEM_ITEM_ID}[{k}]"),
                a.item_id.as_deref(),
                &expected_at(ITEM_ITEM_ID, k),
            );
            assert_eq!((a.client, a.server), (k as u32, 100 + k as u32));
        }
    }

    // --- IEnumString (system proxy) ----------------------------------------------------

    fn assert_all_intact(param: &str, got: &[Option<String>]) {
        assert_eq!(got.len(), probe::ENUM_STRING_LEN, "{param}: {got:?}");
        for (i, s) in got.iter().enumerate() {
            assert_intact(
                &format!("{param}[{i}]"),
                s.as_deref(),
                &expected_at(param, i),
            );
        }
    }

    #[test]
    fn iopcserver_creategroupenumerator_group_names_arrive_intact() {
        let (_com, server) = connect();
        let names = read::group_names(&server.server).expect("CreateGroupEnumerator");
        assert_all_intact(SERVER_GROUP_NAMES, &names);
    }

    #[test]
    fn iopcbrowseserveraddressspace_browseopcitemids_item_ids_arrive_intact() {
        let (_com, server) = connect();
        let bsas = server
            .unknown
            .cast::<IOPCBrowseServerAddressSpace>()
            .expect("IOPCBrowseServerAddressSpace");
        assert_all_intact(
            BSAS_ITEM_IDS,
            &read::browse_item_ids(&bsas).expect("BrowseOPCItemIDs"),
        );
    }

    #[test]
    fn iopcbrowseserveraddressspace_browseaccesspaths_access_paths_arrive_intact() {
        let (_com, server) = connect();
        let bsas = server
            .unknown
            .cast::<IOPCBrowseServerAddressSpace>()
            .expect("IOPCBrowseServerAddressSpace");
        assert_all_intact(
            BSAS_ACCESS_PATHS,
            &read::browse_access_paths(&bsas, "Pompa.Ciśnienie").expect("BrowseAccessPaths"),
        );
    }
}
