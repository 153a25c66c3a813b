//! The proxy/stub DLL `opc_ps.dll`: marshalling code for every interface in `idl/`
//! (OPC Common 1.10 and OPC DA 2.05a/3.0), a full replacement of the OPC Foundation's
//! `opcproxy.dll` + `opccomn_ps.dll`.
//!
//! Built for both bitnesses from the same IDL (`build_proxy` per [`Arch`]): the 64-bit DLL
//! into `target/x86_64-pc-windows-gnu/release/`, the 32-bit one (for 32-bit OPC clients,
//! registered with the 32-bit `regsvr32` of syswow64) into
//! `target/i686-pc-windows-gnu/release/`. The only differences are the tools
//! (`x86_64-`/`i686-w64-mingw32-`) and widl's `-m64`/`-m32`; the widl-bug-2 fix and its
//! check against the IDL run on each.
//!
//! Recipe (`build_proxy`, shown for 64-bit):
//! 1. `x86_64-w64-mingw32-widl -m64 -Oicf` compiles each IDL unit (`opccomn`, `opcda`)
//!    separately into `<unit>.h`, `<unit>_p.c`, `<unit>_i.c`; `--dlldata-only` writes one
//!    `dlldata.c` listing both proxy files, so one DLL serves both (as MIDL does for a
//!    multi-file proxy DLL; no umbrella IDL is needed).
//! 2. `fix_string_out_params` repairs widl bug 2 (below) in each `_p.c`, and the result
//!    is checked against the IDL: every `[out]`/`[in, out]` string-pointer parameter
//!    declared in the IDL must end up described exactly like MIDL describes it.
//! 3. `x86_64-w64-mingw32-gcc` links the DLL with `idl/ps/opc_ps.def` (the four `Dll*`
//!    exports, PRIVATE) and `-include idl/ps/opc_ps_fix.h` (prototypes of the IUnknown
//!    proxy methods that mingw's rpcproxy.h lacks, and the PSFactoryBuffer CLSID).
//!
//! The build is skipped when the DLL is newer than all inputs (the IDL units, the .def,
//! the fix header and the xtask executable itself, which carries the fixer).
//!
//! # widl bug 2: `[out]` pointers to string pointers
//!
//! In `-Oicf` mode every non-base-type parameter of the procedure format string carries
//! a type offset into the type format string. For `[out, string] LPWSTR *ppString`
//! widl 7.0 emits (real output, `opccomn_p.c`):
//!
//! ```text
//! proc:  /* 190 (parameter ppString) */
//!        NdrFcShort(0x2013),  /* flags: must size, must free, out, srv size=8 */
//!        NdrFcShort(0x10),    /* stack offset = 16 */
//!        NdrFcShort(0x24),    /* type offset = 36 */          <-- wrong
//! type:  /* 32 (LPWSTR *) */
//!        0x11, 0x14,          /* FC_RP [allocated_on_stack] [pointer_deref] */
//!        NdrFcShort(0x2),     /* Offset= 2 (36) */
//!        /* 36 (LPWSTR) */
//!        0x13, 0x8,           /* FC_OP [simple_pointer] */
//!        0x25, 0x5c,          /* FC_C_WSTRING FC_PAD */
//! ```
//!
//! The parameter is not "simple ref" (flag 0x0100 clear), so the NDR engine takes the
//! descriptor at the type offset as the description of the argument itself. Microsoft's
//! MIDL points the same parameter at the `FC_RP` (OPC Foundation opccomn_p.c, MIDL 7.00:
//! `ppString` flags 0x2013, Type Offset=30 -> `0x11, 0x14 FC_RP [alloced_on_stack]
//! [pointer_deref]`, Offset=2 -> `0x13, 0x8 FC_OP [simple_pointer] FC_C_WSTRING`; opcda_p.c
//! for DA 3.0, MIDL 8.00: `GetErrorString ppString` and `Browse pszContinuationPoint`
//! (flags 0x201b) both Type Offset=50 -> the same FC_RP/FC_OP pair). widl skips the
//! `FC_RP`, so the engine treats the caller's `LPWSTR *` as the `LPWSTR` itself and the
//! unmarshalled string pointer never reaches `*ppString`: under Wine the client receives
//! NULL strings. The wire format is identical; only that one offset is wrong.
//!
//! The fix re-points the parameter at its `FC_RP [allocated_on_stack] [pointer_deref]`
//! descriptor, which widl writes immediately before the string pointer with a relative
//! offset of 2 (4 bytes earlier). It applies to `[out]` and `[in, out]` parameters whose
//! type offset lands on a `FC_UP`/`FC_OP`/`FC_FP [simple_pointer]` to a conformant
//! string, and fails if such a parameter is not preceded by that exact `FC_RP`.
//!
//! Not affected (widl already points them at their `FC_RP`, as MIDL does), checked on
//! the generated code: arrays of strings (`[out, size_is(,*pdwCount)] LPWSTR **
//! ppDescriptions`, `LookupItemIDs ppszNewItemIDs`), out structures that contain strings
//! (`OPCSERVERSTATUS **`, `OPCITEMPROPERTIES **`, `OPCBROWSEELEMENT **`,
//! `OPCITEMATTRIBUTES **`), out interface pointers, `[in, string] LPCWSTR` (simple ref,
//! pointing at the string) and `[in, size_is(n)] LPCWSTR *` (simple ref, pointing at the
//! array).
//!
//! Re-pointed parameters with the current IDL (10; inherited methods of
//! IOPCGroupStateMgt2 share the procedure of IOPCGroupStateMgt):
//! - opccomn: `IOPCCommon::GetErrorString(ppString)`,
//!   `IOPCServerList::GetClassDetails(ppszProgID, ppszUserType)`,
//!   `IOPCServerList2::GetClassDetails(ppszProgID, ppszUserType, ppszVerIndProgID)`
//! - opcda: `IOPCServer::GetErrorString(ppString)`,
//!   `IOPCBrowseServerAddressSpace::GetItemID(szItemID)`,
//!   `IOPCGroupStateMgt::GetState(ppName)`, `IOPCBrowse::Browse(pszContinuationPoint)`
//!
//! Widl bug 1 (`[in, string, size_is(n)] LPWSTR *` pointing into the middle of an array
//! descriptor) is avoided in the IDL itself by leaving out the redundant `[string]`.

use std::collections::BTreeSet;
use std::fs;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::SystemTime;

use crate::arch::Arch;
use crate::util;

/// IDL compilation units in `idl/`, in the order of the DLL's proxy file list.
const UNITS: &[&str] = &["opccomn", "opcda"];
/// System IDL files (oaidl.idl, objidl.idl, ...) come only with Debian's libwine-dev.
const WINE_IDL_DIR: &str = "/usr/include/wine/wine/windows";
const DLL_NAME: &str = "opc_ps.dll";
const DEF_FILE: &str = "idl/ps/opc_ps.def";
const FIX_HEADER: &str = "idl/ps/opc_ps_fix.h";
const INSTALL_HINT: &str = "cargo xtask setup (or apt-get install -y --no-install-recommends gcc-mingw-w64-x86-64 gcc-mingw-w64-i686 mingw-w64-tools libwine-dev)";

/// Where [`build_proxy`] puts `opc_ps.dll` for `arch`.
pub fn dll_path(root: &Path, arch: Arch) -> PathBuf {
    arch.release_dir(root).join(DLL_NAME)
}

/// Builds both `opc_ps.dll`s (64-bit, then 32-bit) and returns their paths in that order.
pub fn build_both(root: &Path) -> Result<Vec<PathBuf>, String> {
    Arch::ALL.iter().map(|&a| build_proxy(root, a)).collect()
}

/// Builds `opc_ps.dll` for `arch` from `idl/` into `target/<triple>/release` (generated C
/// sources go to its `opc_ps/`) and returns the DLL's path. Skips the work when the DLL
/// is newer than every input.
pub fn build_proxy(root: &Path, arch: Arch) -> Result<PathBuf, String> {
    let out_dir = arch.release_dir(root);
    fs::create_dir_all(&out_dir)
        .map_err(|e| format!("proxy: cannot create {}: {e}", out_dir.display()))?;
    let out_dir = out_dir.as_path();
    let idl_dir = root.join("idl");
    let def = root.join(DEF_FILE);
    let fix_header = root.join(FIX_HEADER);
    let mut inputs: Vec<PathBuf> = UNITS
        .iter()
        .map(|u| idl_dir.join(format!("{u}.idl")))
        .collect();
    inputs.push(def.clone());
    inputs.push(fix_header.clone());
    for input in &inputs {
        if !input.is_file() {
            return Err(format!("proxy: missing input {}", input.display()));
        }
    }
    // The fixer below is part of the recipe: a rebuilt xtask regenerates the DLL.
    if let Ok(exe) = std::env::current_exe() {
        inputs.push(exe);
    }

    let dll = out_dir.join(DLL_NAME);
    if is_up_to_date(&dll, &inputs) {
        println!("proxy: {} is up to date", dll.display());
        return Ok(dll);
    }
    for tool in [arch.widl(), arch.gcc()] {
        if !tool_exists(tool) {
            return Err(format!(
                "proxy: `{tool}` not found; install it with: {INSTALL_HINT}"
            ));
        }
    }
    if !Path::new(WINE_IDL_DIR).join("oaidl.idl").is_file() {
        return Err(format!(
            "proxy: {WINE_IDL_DIR}/oaidl.idl not found; install it with: {INSTALL_HINT}"
        ));
    }

    let gen = out_dir.join("opc_ps");
    fs::create_dir_all(&gen).map_err(|e| format!("proxy: cannot create {}: {e}", gen.display()))?;

    for unit in UNITS {
        let idl = idl_dir.join(format!("{unit}.idl"));
        // Relative output names (cwd = gen) keep absolute paths out of the #includes.
        util::run(
            Command::new(arch.widl())
                .current_dir(&gen)
                .args([arch.widl_m(), "-Oicf"])
                .arg(format!("-I{WINE_IDL_DIR}"))
                .arg(format!("-I{}", idl_dir.display()))
                .args(["-h", "-H", &format!("{unit}.h")])
                .args(["-p", "-P", &format!("{unit}_p.c")])
                .args(["-u", "-U", &format!("{unit}_i.c")])
                .arg(&idl),
        )
        .map_err(|e| format!("proxy: {e}"))?;

        let p_c = gen.join(format!("{unit}_p.c"));
        let generated = read(&p_c)?;
        let fixed = fix_string_out_params(&generated)
            .map_err(|e| format!("proxy: {}: {e}", p_c.display()))?;
        let declared = string_out_params_in_idl(&read(&idl)?)
            .map_err(|e| format!("proxy: {}: {e}", idl.display()))?;
        check_against_idl(&fixed, &declared)
            .map_err(|e| format!("proxy: {}: {e}", p_c.display()))?;
        fs::write(&p_c, &fixed.source)
            .map_err(|e| format!("proxy: cannot write {}: {e}", p_c.display()))?;
        println!(
            "proxy: {}/{unit}_p.c: re-pointed {} string out-parameter(s) at their FC_RP descriptor (widl bug 2){}{}",
            arch.target(),
            fixed.repointed.len(),
            if fixed.repointed.is_empty() { "" } else { ": " },
            fixed.repointed.join(", ")
        );
    }

    let mut dlldata = Command::new(arch.widl());
    dlldata
        .current_dir(&gen)
        .args([arch.widl_m(), "--dlldata-only", "-o", "dlldata.c"])
        .args(UNITS);
    util::run(&mut dlldata).map_err(|e| format!("proxy: {e}"))?;

    // Link to a temporary name so that a failed link never leaves an "up to date" DLL.
    let tmp = out_dir.join(format!("{DLL_NAME}.tmp"));
    let mut gcc = Command::new(arch.gcc());
    gcc.current_dir(&gen)
        .args(["-O2", "-shared", "-include"])
        .arg(&fix_header)
        .args(["-DREGISTER_PROXY_DLL", "-DWIN32_LEAN_AND_MEAN", "-o"])
        .arg(&tmp)
        .arg("dlldata.c");
    for unit in UNITS {
        gcc.arg(format!("{unit}_p.c")).arg(format!("{unit}_i.c"));
    }
    gcc.arg(&def)
        .args(["-lrpcrt4", "-loleaut32", "-lole32", "-luuid"]);
    if arch == Arch::X86 {
        // The .def names the undecorated Dll* functions; ld maps them to their stdcall
        // symbols (_DllGetClassObject@12, ...), as it would with a warning each.
        gcc.arg("-Wl,--enable-stdcall-fixup");
    }
    util::run(&mut gcc).map_err(|e| format!("proxy: {e}"))?;
    fs::rename(&tmp, &dll).map_err(|e| {
        format!(
            "proxy: cannot rename {} to {}: {e}",
            tmp.display(),
            dll.display()
        )
    })?;
    println!("proxy: built {}", dll.display());
    Ok(dll)
}

fn read(path: &Path) -> Result<String, String> {
    fs::read_to_string(path).map_err(|e| format!("proxy: cannot read {}: {e}", path.display()))
}

fn tool_exists(tool: &str) -> bool {
    Command::new(tool).arg("--version").output().is_ok()
}

fn mtime(path: &Path) -> Option<SystemTime> {
    fs::metadata(path).and_then(|m| m.modified()).ok()
}

/// True if `output` exists and is at least as new as every input.
fn is_up_to_date(output: &Path, inputs: &[PathBuf]) -> bool {
    let Some(out) = mtime(output) else {
        return false;
    };
    inputs.iter().all(|i| mtime(i).is_some_and(|t| t <= out))
}

// ------------------------------------------------------------------------------------
// The fixer for widl bug 2

// NDR format characters and flags used below (names as in Microsoft's ndrtypes.h).
const FC_RP: u8 = 0x11;
const FC_UP: u8 = 0x12;
const FC_OP: u8 = 0x13;
const FC_FP: u8 = 0x14;
const FC_C_CSTRING: u8 = 0x22;
const FC_C_WSTRING: u8 = 0x25;
const FC_ALLOCED_ON_STACK: u8 = 0x04;
const FC_SIMPLE_POINTER: u8 = 0x08;
const FC_POINTER_DEREF: u8 = 0x10;
// PARAM_ATTRIBUTES bits of a -Oicf parameter description.
const PARAM_IS_OUT: u16 = 0x0010;
const PARAM_IS_BASETYPE: u16 = 0x0040;
const PARAM_IS_SIMPLE_REF: u16 = 0x0100;

/// The result of `fix_string_out_params`. Parameters are named `Interface::Method(param)`.
#[derive(Debug)]
pub struct StringOutFix {
    /// The corrected `_p.c` text.
    pub source: String,
    /// Parameters whose type offset was moved back onto their `FC_RP`.
    pub repointed: Vec<String>,
    /// String out-parameters that already pointed at their `FC_RP` (none with widl 7.0).
    pub already_correct: Vec<String>,
}

/// One line of a format string array: an offset annotation (`/* 32 (LPWSTR *) */`) or
/// a line of code (`0x11, 0x14, /* FC_RP ... */`), with its byte range in the source.
#[derive(Debug)]
enum Item<'a> {
    Mark {
        offset: usize,
        label: &'a str,
    },
    Code {
        bytes: Vec<u8>,
        comment: &'a str,
        start: usize,
        end: usize,
    },
}

/// A parsed `static const MIDL_*_FORMAT_STRING name = { 0, { ... } };` array.
#[derive(Debug)]
struct FormatArray<'a> {
    bytes: Vec<u8>,
    items: Vec<Item<'a>>,
}

/// A parameter description of the procedure format string.
#[derive(Debug)]
struct Param {
    name: String,
    flags: u16,
    type_offset: usize,
    /// Byte range in the source of the `NdrFcShort(type offset)` line (without newline).
    line: (usize, usize),
}

/// Re-points every `[out]`/`[in, out]` parameter whose type offset skips its
/// `FC_RP [allocated_on_stack] [pointer_deref]` descriptor and lands on a string pointer
/// (widl bug 2, see the module documentation). Strict: any unexpected shape of the
/// generated code is an error.
pub fn fix_string_out_params(src: &str) -> Result<StringOutFix, String> {
    let proc_size = define_value(src, "PROC_FORMAT_STRING_SIZE")?;
    let type_size = define_value(src, "TYPE_FORMAT_STRING_SIZE")?;
    let procs = parse_array(src, "__MIDL_ProcFormatString")?;
    let types = parse_array(src, "__MIDL_TypeFormatString")?;
    if procs.bytes.len() != proc_size {
        return Err(format!(
            "__MIDL_ProcFormatString has {} bytes, PROC_FORMAT_STRING_SIZE is {proc_size}",
            procs.bytes.len()
        ));
    }
    if types.bytes.len() != type_size {
        return Err(format!(
            "__MIDL_TypeFormatString has {} bytes, TYPE_FORMAT_STRING_SIZE is {type_size}",
            types.bytes.len()
        ));
    }
    let params = parse_params(&procs)?;
    if params.is_empty() {
        return Err("no parameter descriptions with a type offset found".into());
    }

    let t = &types.bytes;
    let mut repointed = Vec::new();
    let mut already_correct = Vec::new();
    let mut edits: Vec<((usize, usize), String)> = Vec::new();
    for p in &params {
        if p.type_offset + 2 > t.len() {
            return Err(format!(
                "{}: type offset {} is outside the type format string",
                p.name, p.type_offset
            ));
        }
        if p.flags & PARAM_IS_OUT == 0 {
            continue;
        }
        let at = p.type_offset;
        if p.flags & PARAM_IS_SIMPLE_REF == 0 && is_string_pointer(t, at) {
            // The bug: the FC_RP describing the argument must sit 4 bytes earlier and
            // point (relative offset 2) at this string pointer.
            if at < 4 || stack_rp_target(t, at - 4) != Some(at) {
                return Err(format!(
                    "{}: type offset {at} lands on a string pointer that is not preceded by its \
                     FC_RP [allocated_on_stack] [pointer_deref] descriptor; widl's output changed, \
                     update the fixer",
                    p.name
                ));
            }
            let new = at - 4;
            let line = &src[p.line.0..p.line.1];
            let indent = &line[..line.len() - line.trim_start().len()];
            edits.push((
                p.line,
                format!("{indent}NdrFcShort(0x{new:x}),\t/* type offset = {new} (xtask proxy: was {at}, widl bug 2) */"),
            ));
            repointed.push(p.name.clone());
        } else if let Some(target) = stack_rp_target(t, at) {
            if is_string_pointer(t, target) {
                already_correct.push(p.name.clone());
            }
        }
    }

    let mut source = src.to_string();
    edits.sort_by_key(|(range, _)| std::cmp::Reverse(range.0));
    for ((start, end), text) in edits {
        source.replace_range(start..end, &text);
    }
    Ok(StringOutFix {
        source,
        repointed,
        already_correct,
    })
}

/// `FC_UP`/`FC_OP`/`FC_FP [simple_pointer]` to a conformant (w)string at `at`.
fn is_string_pointer(t: &[u8], at: usize) -> bool {
    at + 3 <= t.len()
        && matches!(t[at], FC_UP | FC_OP | FC_FP)
        && t[at + 1] & FC_SIMPLE_POINTER != 0
        && matches!(t[at + 2], FC_C_CSTRING | FC_C_WSTRING)
}

/// If an `FC_RP [allocated_on_stack] [pointer_deref]` descriptor starts at `at`, the
/// offset of its pointee.
fn stack_rp_target(t: &[u8], at: usize) -> Option<usize> {
    if at + 4 > t.len() || t[at] != FC_RP || t[at + 1] != FC_ALLOCED_ON_STACK | FC_POINTER_DEREF {
        return None;
    }
    let rel = i16::from_le_bytes([t[at + 2], t[at + 3]]);
    usize::try_from(at as isize + 2 + rel as isize).ok()
}

/// The value of `#define NAME <decimal>`.
fn define_value(src: &str, name: &str) -> Result<usize, String> {
    let prefix = format!("#define {name} ");
    let mut found = src.lines().filter_map(|l| l.strip_prefix(prefix.as_str()));
    let value = found
        .next()
        .ok_or_else(|| format!("`#define {name}` not found"))?;
    if found.next().is_some() {
        return Err(format!("`#define {name}` appears twice"));
    }
    value
        .trim()
        .parse()
        .map_err(|_| format!("`#define {name} {value}` is not a number"))
}

/// Parses the array `static const ... <name> = { 0, { <bytes> } };`, checking every offset
/// annotation against the running byte count.
fn parse_array<'a>(src: &'a str, name: &str) -> Result<FormatArray<'a>, String> {
    let marker = format!("{name} =");
    let mut hits = src.match_indices(marker.as_str());
    let (at, _) = hits.next().ok_or_else(|| format!("`{marker}` not found"))?;
    if hits.next().is_some() {
        return Err(format!("`{marker}` appears twice"));
    }
    // Header: `= { 0, {` (the first 0 is the Pad member).
    let after = at + marker.len();
    let outer = after
        + src[after..]
            .find('{')
            .ok_or_else(|| format!("{name}: no opening brace"))?;
    let inner = outer
        + 1
        + src[outer + 1..]
            .find('{')
            .ok_or_else(|| format!("{name}: no inner brace"))?;
    let pad: String = src[outer + 1..inner]
        .chars()
        .filter(|c| !c.is_whitespace())
        .collect();
    if !src[after..outer].trim().is_empty() || pad != "0," {
        return Err(format!(
            "{name}: expected `= {{ 0, {{` at the start of the array"
        ));
    }
    let body_start = inner + 1;
    let close = body_start
        + src[body_start..]
            .find('}')
            .ok_or_else(|| format!("{name}: no closing brace"))?;
    let tail = &src[close + 1..];
    if !tail.trim_start().starts_with("};") {
        return Err(format!("{name}: expected `}};` after the byte list"));
    }

    let mut items = Vec::new();
    let mut bytes = Vec::new();
    let mut pos = body_start;
    for raw in src[body_start..close].split_inclusive('\n') {
        let line = raw.trim_end_matches(['\n', '\r']);
        let (start, end) = (pos, pos + line.len());
        pos += raw.len();
        let text = line.trim();
        if text.is_empty() {
            continue;
        }
        if let Some(comment) = text.strip_prefix("/*") {
            let inside = comment
                .strip_suffix("*/")
                .ok_or_else(|| format!("{name}: unterminated comment line `{text}`"))?
                .trim();
            let (number, rest) = inside.split_once(' ').unwrap_or((inside, ""));
            let offset: usize = number.parse().map_err(|_| {
                format!("{name}: comment line `{text}` is not an offset annotation")
            })?;
            if offset != bytes.len() {
                return Err(format!(
                    "{name}: annotation `{text}` but the byte offset is {}",
                    bytes.len()
                ));
            }
            let label = rest.trim();
            let label = if label.is_empty() {
                ""
            } else {
                label
                    .strip_prefix('(')
                    .and_then(|l| l.strip_suffix(')'))
                    .ok_or_else(|| format!("{name}: malformed annotation `{text}`"))?
            };
            items.push(Item::Mark { offset, label });
            continue;
        }
        let (code, comment) = match text.find("/*") {
            Some(i) => {
                let c = text[i + 2..].strip_suffix("*/").ok_or_else(|| {
                    format!("{name}: trailing comment not at the end of `{text}`")
                })?;
                (&text[..i], c.trim())
            }
            None => (text, ""),
        };
        let mut line_bytes = Vec::new();
        for token in code.split(',').map(str::trim).filter(|t| !t.is_empty()) {
            line_bytes.extend(parse_token(token).map_err(|e| format!("{name}: {e} in `{text}`"))?);
        }
        if line_bytes.is_empty() {
            return Err(format!("{name}: no bytes in line `{text}`"));
        }
        bytes.extend_from_slice(&line_bytes);
        items.push(Item::Code {
            bytes: line_bytes,
            comment,
            start,
            end,
        });
    }
    Ok(FormatArray { bytes, items })
}

/// `NdrFcShort(x)` (2 bytes, little endian), `NdrFcLong(x)` (4 bytes) or a byte literal.
fn parse_token(token: &str) -> Result<Vec<u8>, String> {
    let call = |prefix: &str| token.strip_prefix(prefix).and_then(|t| t.strip_suffix(')'));
    if let Some(arg) = call("NdrFcShort(") {
        let v = parse_int(arg)?;
        let v = u16::try_from(v).map_err(|_| format!("NdrFcShort({arg}) out of range"))?;
        Ok(v.to_le_bytes().to_vec())
    } else if let Some(arg) = call("NdrFcLong(") {
        let v = parse_int(arg)?;
        let v = u32::try_from(v).map_err(|_| format!("NdrFcLong({arg}) out of range"))?;
        Ok(v.to_le_bytes().to_vec())
    } else {
        let v = parse_int(token)?;
        let v = u8::try_from(v).map_err(|_| format!("byte {token} out of range"))?;
        Ok(vec![v])
    }
}

fn parse_int(s: &str) -> Result<u64, String> {
    let s = s.trim();
    let parsed = match s.strip_prefix("0x").or_else(|| s.strip_prefix("0X")) {
        Some(hex) => u64::from_str_radix(hex, 16),
        None => s.parse(),
    };
    parsed.map_err(|_| format!("unexpected token `{s}`"))
}

/// Walks the procedure format string: `(procedure I::M)`, then per parameter
/// `(parameter p)` + flags + stack offset + (type offset | base type), `(return value)`.
fn parse_params(procs: &FormatArray) -> Result<Vec<Param>, String> {
    let code = |i: usize| match procs.items.get(i) {
        Some(Item::Code {
            bytes,
            comment,
            start,
            end,
        }) => Some((bytes.as_slice(), *comment, (*start, *end))),
        _ => None,
    };
    let mut out = Vec::new();
    let mut procedure: Option<&str> = None;
    for (i, item) in procs.items.iter().enumerate() {
        let Item::Mark { offset, label } = item else {
            continue;
        };
        if let Some(name) = label.strip_prefix("procedure ") {
            procedure = Some(name);
            continue;
        }
        if *label == "return value" {
            continue;
        }
        let Some(param) = label.strip_prefix("parameter ") else {
            return Err(format!(
                "__MIDL_ProcFormatString: unexpected annotation `{offset} ({label})`"
            ));
        };
        let proc_name =
            procedure.ok_or_else(|| format!("parameter {param} before any procedure"))?;
        let name = format!("{proc_name}({param})");
        let bad =
            || format!("{name}: unexpected parameter description (flags, stack offset, type)");
        let (flags, flags_comment, _) = code(i + 1).ok_or_else(bad)?;
        let (stack, stack_comment, _) = code(i + 2).ok_or_else(bad)?;
        let (ty, ty_comment, ty_line) = code(i + 3).ok_or_else(bad)?;
        if flags.len() != 2 || !flags_comment.starts_with("flags:") {
            return Err(bad());
        }
        if stack.len() != 2 || !stack_comment.starts_with("stack offset") {
            return Err(bad());
        }
        let flags = u16::from_le_bytes([flags[0], flags[1]]);
        if flags & PARAM_IS_BASETYPE != 0 {
            // The format character of the base type (its 0 filler byte follows).
            if ty.len() != 1 {
                return Err(bad());
            }
            continue;
        }
        if ty.len() != 2 || !ty_comment.starts_with("type offset") {
            return Err(format!(
                "{name}: expected `NdrFcShort(..), /* type offset = .. */`"
            ));
        }
        out.push(Param {
            name,
            flags,
            type_offset: usize::from(u16::from_le_bytes([ty[0], ty[1]])),
            line: ty_line,
        });
    }
    Ok(out)
}

/// Checks that the fixed code describes exactly the string out-parameters that the IDL
/// declares: each one points at its `FC_RP`, and nothing else was touched.
fn check_against_idl(fix: &StringOutFix, declared: &BTreeSet<String>) -> Result<(), String> {
    let handled: BTreeSet<String> = fix
        .repointed
        .iter()
        .chain(&fix.already_correct)
        .cloned()
        .collect();
    if fix.repointed.len() + fix.already_correct.len() != handled.len() {
        return Err("a parameter was found twice".into());
    }
    let missing: Vec<_> = declared.difference(&handled).cloned().collect();
    let unexpected: Vec<_> = handled.difference(declared).cloned().collect();
    if missing.is_empty() && unexpected.is_empty() {
        return Ok(());
    }
    Err(format!(
        "string out-parameters differ between IDL and generated code; declared in the IDL \
         but not found: [{}]; found but not declared as `[out] LPWSTR *` in the IDL: [{}]",
        missing.join(", "),
        unexpected.join(", ")
    ))
}

// ------------------------------------------------------------------------------------
// A small reader of our IDL files (conventional layout, see idl/*.idl)

/// The `[out]`/`[in, out]` parameters declared as a single pointer to a string pointer
/// (`LPWSTR *`, `LPOLESTR *`, ... without `size_is`), named `Interface::Method(param)`.
pub fn string_out_params_in_idl(idl: &str) -> Result<BTreeSet<String>, String> {
    const STRING_TYPES: &[&str] = &[
        "LPWSTR",
        "LPCWSTR",
        "LPOLESTR",
        "LPCOLESTR",
        "LPSTR",
        "LPCSTR",
    ];
    let text = strip_comments(idl);
    let mut out = BTreeSet::new();
    let mut rest = text.as_str();
    while let Some(at) = find_keyword(rest, "interface") {
        let after = &rest[at + "interface".len()..];
        let name: String = after
            .trim_start()
            .chars()
            .take_while(|c| c.is_alphanumeric() || *c == '_')
            .collect();
        let Some(open) = after.find(['{', ';']) else {
            break;
        };
        if after.as_bytes()[open] == b';' {
            // Forward declaration.
            rest = &after[open + 1..];
            continue;
        }
        let body_start = open + 1;
        let close = body_start
            + after[body_start..]
                .find('}')
                .ok_or_else(|| format!("interface {name}: no closing brace"))?;
        for decl in after[body_start..close].split(';') {
            let decl = decl.trim();
            if decl.is_empty() || decl.starts_with("typedef") {
                continue;
            }
            let (Some(lp), Some(rp)) = (decl.find('('), decl.rfind(')')) else {
                return Err(format!(
                    "interface {name}: cannot read declaration `{decl}`"
                ));
            };
            let method = decl[..lp].split_whitespace().last().unwrap_or_default();
            for param in split_top_level(&decl[lp + 1..rp]) {
                let param = param.trim();
                if param.is_empty() || param == "void" {
                    continue;
                }
                let (attrs, decl) = match param.strip_prefix('[') {
                    Some(p) => {
                        let end = p
                            .find(']')
                            .ok_or_else(|| format!("{name}::{method}: unclosed `[`"))?;
                        (&p[..end], &p[end + 1..])
                    }
                    None => ("", param),
                };
                let attrs: Vec<&str> = split_top_level(attrs)
                    .into_iter()
                    .map(|a| a.trim().split('(').next().unwrap_or_default().trim())
                    .collect();
                let compact: String = decl.chars().filter(|c| !c.is_whitespace()).collect();
                let pname: String = compact
                    .chars()
                    .rev()
                    .take_while(|c| c.is_alphanumeric() || *c == '_')
                    .collect::<Vec<_>>()
                    .into_iter()
                    .rev()
                    .collect();
                let ty = &compact[..compact.len() - pname.len()];
                let is_string_ptr = ty
                    .strip_suffix('*')
                    .is_some_and(|base| STRING_TYPES.contains(&base));
                let sized = attrs.iter().any(|a| a.ends_with("_is") && *a != "iid_is");
                if attrs.contains(&"out") && is_string_ptr && !sized {
                    out.insert(format!("{name}::{method}({pname})"));
                }
            }
        }
        rest = &after[close + 1..];
    }
    Ok(out)
}

/// Byte index of `word` as a whole word in `s`.
fn find_keyword(s: &str, word: &str) -> Option<usize> {
    let is_ident = |c: char| c.is_alphanumeric() || c == '_';
    let mut from = 0;
    while let Some(i) = s[from..].find(word).map(|i| i + from) {
        let before = s[..i].chars().next_back().is_some_and(is_ident);
        let after = s[i + word.len()..].chars().next().is_some_and(is_ident);
        if !before && !after {
            return Some(i);
        }
        from = i + word.len();
    }
    None
}

/// Splits at commas outside (), [] and {}.
fn split_top_level(s: &str) -> Vec<&str> {
    let mut parts = Vec::new();
    let (mut depth, mut start) = (0i32, 0);
    for (i, c) in s.char_indices() {
        match c {
            '(' | '[' | '{' => depth += 1,
            ')' | ']' | '}' => depth -= 1,
            ',' if depth == 0 => {
                parts.push(&s[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    parts.push(&s[start..]);
    parts
}

/// Removes `//` and `/* */` comments and the contents of string literals (cpp_quote,
/// L"..." constants), keeping line structure.
fn strip_comments(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    let mut chars = s.chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            '/' if chars.peek() == Some(&'/') => {
                for n in chars.by_ref() {
                    if n == '\n' {
                        out.push('\n');
                        break;
                    }
                }
            }
            '/' if chars.peek() == Some(&'*') => {
                chars.next();
                let mut prev = ' ';
                for n in chars.by_ref() {
                    if prev == '*' && n == '/' {
                        break;
                    }
                    prev = n;
                }
                out.push(' ');
            }
            '"' => {
                out.push('"');
                let mut escaped = false;
                for n in chars.by_ref() {
                    if n == '"' && !escaped {
                        break;
                    }
                    escaped = n == '\\' && !escaped;
                }
                out.push('"');
            }
            _ => out.push(c),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The IDL that `FIXTURE` was generated from (`x86_64-w64-mingw32-widl` 7.0,
    /// `-m64 -Oicf -p`): IOPCCommon as in idl/opccomn.idl, plus an IOPCBrowse cut down to
    /// the `[in, out, string] LPWSTR *` of Browse.
    const FIXTURE_IDL: &str = r#"
import "unknwn.idl";
[object, uuid(F31DFDE2-07B6-11d2-B2D8-0060083BA1FB), pointer_default(unique)]
interface IOPCCommon : IUnknown
{
    HRESULT SetLocaleID([in] LCID dwLcid);
    HRESULT GetLocaleID([out] LCID* pdwLcid);
    HRESULT QueryAvailableLocaleIDs([out] DWORD* pdwCount, [out, size_is(,*pdwCount)] LCID** pdwLcid);
    HRESULT GetErrorString([in] HRESULT dwError, [out, string] LPWSTR* ppString);
    HRESULT SetClientName([in, string] LPCWSTR szName);
}
[object, uuid(39227004-A18F-4b57-8B0A-5235670F4468), pointer_default(unique)]
interface IOPCBrowse : IUnknown
{
    HRESULT Browse([in, string] LPWSTR szItemID, [in, out, string] LPWSTR* pszContinuationPoint, [out] DWORD* pdwCount);
}
"#;

    /// Excerpt of the real widl output for `FIXTURE_IDL` (the two size defines and the
    /// two format string arrays, byte for byte; tabs written as \t).
    const FIXTURE: &str = "
#define TYPE_FORMAT_STRING_SIZE 57
#define PROC_FORMAT_STRING_SIZE 253

static const MIDL_PROC_FORMAT_STRING __MIDL_ProcFormatString =
{
    0,
    {
/* 0 (procedure IOPCCommon::SetLocaleID) */
        0x33,\t/* FC_AUTO_HANDLE */
        0x6c,
        NdrFcLong(0x0),
        NdrFcShort(0x3),\t/* method 3 */
        NdrFcShort(0x18),\t/* stack size = 24 */
        NdrFcShort(0x8),\t/* client buffer = 8 */
        NdrFcShort(0x8),\t/* server buffer = 8 */
        0x44,
        0x02,\t/* 2 params */
        0x0a,
        0x00,
        NdrFcShort(0x0),
        NdrFcShort(0x0),
        NdrFcShort(0x0),
        NdrFcShort(0x0),
/* 26 (parameter dwLcid) */
        NdrFcShort(0x48),\t/* flags: in, base type */
        NdrFcShort(0x8),\t/* stack offset = 8 */
        0x08,\t/* FC_LONG */
        0x0,
/* 32 (return value) */
        NdrFcShort(0x70),\t/* flags: out, return, base type */
        NdrFcShort(0x10),\t/* stack offset = 16 */
        0x08,\t/* FC_LONG */
        0x0,
/* 38 (procedure IOPCCommon::GetLocaleID) */
        0x33,\t/* FC_AUTO_HANDLE */
        0x6c,
        NdrFcLong(0x0),
        NdrFcShort(0x4),\t/* method 4 */
        NdrFcShort(0x18),\t/* stack size = 24 */
        NdrFcShort(0x0),\t/* client buffer = 0 */
        NdrFcShort(0x10),\t/* server buffer = 16 */
        0x44,
        0x02,\t/* 2 params */
        0x0a,
        0x00,
        NdrFcShort(0x0),
        NdrFcShort(0x0),
        NdrFcShort(0x0),
        NdrFcShort(0x0),
/* 64 (parameter pdwLcid) */
        NdrFcShort(0x2150),\t/* flags: out, base type, simple ref, srv size=8 */
        NdrFcShort(0x8),\t/* stack offset = 8 */
        0x09,\t/* FC_ULONG */
        0x0,
/* 70 (return value) */
        NdrFcShort(0x70),\t/* flags: out, return, base type */
        NdrFcShort(0x10),\t/* stack offset = 16 */
        0x08,\t/* FC_LONG */
        0x0,
/* 76 (procedure IOPCCommon::QueryAvailableLocaleIDs) */
        0x33,\t/* FC_AUTO_HANDLE */
        0x6c,
        NdrFcLong(0x0),
        NdrFcShort(0x5),\t/* method 5 */
        NdrFcShort(0x20),\t/* stack size = 32 */
        NdrFcShort(0x0),\t/* client buffer = 0 */
        NdrFcShort(0x10),\t/* server buffer = 16 */
        0x45,
        0x03,\t/* 3 params */
        0x0a,
        0x00,
        NdrFcShort(0x0),
        NdrFcShort(0x0),
        NdrFcShort(0x0),
        NdrFcShort(0x0),
/* 102 (parameter pdwCount) */
        NdrFcShort(0x2150),\t/* flags: out, base type, simple ref, srv size=8 */
        NdrFcShort(0x8),\t/* stack offset = 8 */
        0x09,\t/* FC_ULONG */
        0x0,
/* 108 (parameter pdwLcid) */
        NdrFcShort(0x2013),\t/* flags: must size, must free, out, srv size=8 */
        NdrFcShort(0x10),\t/* stack offset = 16 */
        NdrFcShort(0x18),\t/* type offset = 24 */
/* 114 (return value) */
        NdrFcShort(0x70),\t/* flags: out, return, base type */
        NdrFcShort(0x18),\t/* stack offset = 24 */
        0x08,\t/* FC_LONG */
        0x0,
/* 120 (procedure IOPCCommon::GetErrorString) */
        0x33,\t/* FC_AUTO_HANDLE */
        0x6c,
        NdrFcLong(0x0),
        NdrFcShort(0x6),\t/* method 6 */
        NdrFcShort(0x20),\t/* stack size = 32 */
        NdrFcShort(0x8),\t/* client buffer = 8 */
        NdrFcShort(0x8),\t/* server buffer = 8 */
        0x45,
        0x03,\t/* 3 params */
        0x0a,
        0x00,
        NdrFcShort(0x0),
        NdrFcShort(0x0),
        NdrFcShort(0x0),
        NdrFcShort(0x0),
/* 146 (parameter dwError) */
        NdrFcShort(0x48),\t/* flags: in, base type */
        NdrFcShort(0x8),\t/* stack offset = 8 */
        0x08,\t/* FC_LONG */
        0x0,
/* 152 (parameter ppString) */
        NdrFcShort(0x2013),\t/* flags: must size, must free, out, srv size=8 */
        NdrFcShort(0x10),\t/* stack offset = 16 */
        NdrFcShort(0x20),\t/* type offset = 32 */
/* 158 (return value) */
        NdrFcShort(0x70),\t/* flags: out, return, base type */
        NdrFcShort(0x18),\t/* stack offset = 24 */
        0x08,\t/* FC_LONG */
        0x0,
/* 164 (procedure IOPCCommon::SetClientName) */
        0x33,\t/* FC_AUTO_HANDLE */
        0x6c,
        NdrFcLong(0x0),
        NdrFcShort(0x7),\t/* method 7 */
        NdrFcShort(0x18),\t/* stack size = 24 */
        NdrFcShort(0x0),\t/* client buffer = 0 */
        NdrFcShort(0x8),\t/* server buffer = 8 */
        0x46,
        0x02,\t/* 2 params */
        0x0a,
        0x00,
        NdrFcShort(0x0),
        NdrFcShort(0x0),
        NdrFcShort(0x0),
        NdrFcShort(0x0),
/* 190 (parameter szName) */
        NdrFcShort(0x10b),\t/* flags: must size, must free, in, simple ref */
        NdrFcShort(0x8),\t/* stack offset = 8 */
        NdrFcShort(0x26),\t/* type offset = 38 */
/* 196 (return value) */
        NdrFcShort(0x70),\t/* flags: out, return, base type */
        NdrFcShort(0x10),\t/* stack offset = 16 */
        0x08,\t/* FC_LONG */
        0x0,
/* 202 (procedure IOPCBrowse::Browse) */
        0x33,\t/* FC_AUTO_HANDLE */
        0x6c,
        NdrFcLong(0x0),
        NdrFcShort(0x3),\t/* method 3 */
        NdrFcShort(0x28),\t/* stack size = 40 */
        NdrFcShort(0x0),\t/* client buffer = 0 */
        NdrFcShort(0x10),\t/* server buffer = 16 */
        0x47,
        0x04,\t/* 4 params */
        0x0a,
        0x00,
        NdrFcShort(0x0),
        NdrFcShort(0x0),
        NdrFcShort(0x0),
        NdrFcShort(0x0),
/* 228 (parameter szItemID) */
        NdrFcShort(0x10b),\t/* flags: must size, must free, in, simple ref */
        NdrFcShort(0x8),\t/* stack offset = 8 */
        NdrFcShort(0x2a),\t/* type offset = 42 */
/* 234 (parameter pszContinuationPoint) */
        NdrFcShort(0x201b),\t/* flags: must size, must free, in, out, srv size=8 */
        NdrFcShort(0x10),\t/* stack offset = 16 */
        NdrFcShort(0x30),\t/* type offset = 48 */
/* 240 (parameter pdwCount) */
        NdrFcShort(0x2150),\t/* flags: out, base type, simple ref, srv size=8 */
        NdrFcShort(0x18),\t/* stack offset = 24 */
        0x09,\t/* FC_ULONG */
        0x0,
/* 246 (return value) */
        NdrFcShort(0x70),\t/* flags: out, return, base type */
        NdrFcShort(0x20),\t/* stack offset = 32 */
        0x08,\t/* FC_LONG */
        0x0,
        0x0
    }
};

static const MIDL_TYPE_FORMAT_STRING __MIDL_TypeFormatString =
{
    0,
    {
        NdrFcShort(0x0),
/* 2 (LCID *) */
        0x11, 0x8,\t/* FC_RP [simple_pointer] */
        0x09,\t/* FC_ULONG */
        0x5c,\t/* FC_PAD */
/* 6 (DWORD *) */
        0x11, 0x8,\t/* FC_RP [simple_pointer] */
        0x09,\t/* FC_ULONG */
        0x5c,\t/* FC_PAD */
/* 10 (LCID *) */
        0x1b,\t/* FC_CARRAY */
        0x3,\t/* 3 */
        NdrFcShort(0x4),\t/* 4 */
        0x29,\t/* Corr desc: parameter pdwCount, FC_ULONG */
        0x54,\t/* FC_DEREFERENCE */
        NdrFcShort(0x8),\t/* offset = 8 */
        0x08,\t/* FC_LONG */
        0x5b,\t/* FC_END */
/* 20 */
        0x13, 0x0,\t/* FC_OP */
        NdrFcShort(0xfff4),\t/* Offset= -12 (10) */
/* 24 (LCID **) */
        0x11, 0x14,\t\t/* FC_RP [allocated_on_stack] [pointer_deref] */
        NdrFcShort(0xfffa),\t/* Offset= -6 (20) */
/* 28 (LPWSTR *) */
        0x11, 0x14,\t\t/* FC_RP [allocated_on_stack] [pointer_deref] */
        NdrFcShort(0x2),\t/* Offset= 2 (32) */
/* 32 (LPWSTR) */
        0x13, 0x8,\t/* FC_OP [simple_pointer] */
/* 34 */
        0x25,\t/* FC_C_WSTRING */
        0x5c,\t/* FC_PAD */
/* 36 (LPCWSTR) */
        0x11, 0x8,\t/* FC_RP [simple_pointer] */
/* 38 */
        0x25,\t/* FC_C_WSTRING */
        0x5c,\t/* FC_PAD */
/* 40 (LPWSTR) */
        0x11, 0x8,\t/* FC_RP [simple_pointer] */
/* 42 */
        0x25,\t/* FC_C_WSTRING */
        0x5c,\t/* FC_PAD */
/* 44 (LPWSTR *) */
        0x11, 0x14,\t\t/* FC_RP [allocated_on_stack] [pointer_deref] */
        NdrFcShort(0x2),\t/* Offset= 2 (48) */
/* 48 (LPWSTR) */
        0x13, 0x8,\t/* FC_OP [simple_pointer] */
/* 50 */
        0x25,\t/* FC_C_WSTRING */
        0x5c,\t/* FC_PAD */
/* 52 (DWORD *) */
        0x11, 0x8,\t/* FC_RP [simple_pointer] */
        0x09,\t/* FC_ULONG */
        0x5c,\t/* FC_PAD */
        0x0
    }
};
";

    const GET_ERROR_STRING: &str = "IOPCCommon::GetErrorString(ppString)";
    const BROWSE: &str = "IOPCBrowse::Browse(pszContinuationPoint)";

    fn params_of(src: &str) -> Vec<(String, u16, usize)> {
        let procs = parse_array(src, "__MIDL_ProcFormatString").unwrap();
        parse_params(&procs)
            .unwrap()
            .into_iter()
            .map(|p| (p.name, p.flags, p.type_offset))
            .collect()
    }

    #[test]
    fn fixture_has_the_widl_bug() {
        let params = params_of(FIXTURE);
        let names: Vec<&str> = params.iter().map(|p| p.0.as_str()).collect();
        assert_eq!(
            names,
            [
                "IOPCCommon::QueryAvailableLocaleIDs(pdwLcid)",
                GET_ERROR_STRING,
                "IOPCCommon::SetClientName(szName)",
                "IOPCBrowse::Browse(szItemID)",
                BROWSE,
            ]
        );
        // ppString: out, not simple ref, type offset on the FC_OP string pointer at 32,
        // past its FC_RP at 28.
        assert_eq!(params[1], (GET_ERROR_STRING.to_string(), 0x2013, 32));
        assert_eq!(params[4], (BROWSE.to_string(), 0x201b, 48));
        let types = parse_array(FIXTURE, "__MIDL_TypeFormatString")
            .unwrap()
            .bytes;
        assert_eq!(types.len(), 57);
        assert_eq!(
            &types[28..36],
            &[0x11, 0x14, 0x02, 0x00, 0x13, 0x08, 0x25, 0x5c]
        );
    }

    #[test]
    fn repoints_string_out_params_at_their_fc_rp() {
        let fix = fix_string_out_params(FIXTURE).unwrap();
        assert_eq!(fix.repointed, [GET_ERROR_STRING, BROWSE]);
        assert!(fix.already_correct.is_empty());

        let before = params_of(FIXTURE);
        let after = params_of(&fix.source);
        let types = parse_array(&fix.source, "__MIDL_TypeFormatString")
            .unwrap()
            .bytes;
        for (old, new) in before.iter().zip(&after) {
            assert_eq!((&old.0, old.1), (&new.0, new.1));
            if old.0 == GET_ERROR_STRING || old.0 == BROWSE {
                assert_eq!(new.2, old.2 - 4, "{}", old.0);
                assert_eq!(stack_rp_target(&types, new.2), Some(old.2), "{}", old.0);
            } else {
                assert_eq!(new.2, old.2, "{} must not move", old.0);
            }
        }
        // Only the two type-offset lines changed, and the byte count is unchanged.
        let changed: Vec<_> = FIXTURE
            .lines()
            .zip(fix.source.lines())
            .filter(|(a, b)| a != b)
            .collect();
        assert_eq!(changed.len(), 2);
        assert_eq!(
            changed[0].0,
            "        NdrFcShort(0x20),\t/* type offset = 32 */"
        );
        assert_eq!(
            changed[0].1,
            "        NdrFcShort(0x1c),\t/* type offset = 28 (xtask proxy: was 32, widl bug 2) */"
        );
        assert_eq!(FIXTURE.lines().count(), fix.source.lines().count());
    }

    #[test]
    fn fixing_twice_changes_nothing() {
        let once = fix_string_out_params(FIXTURE).unwrap();
        let twice = fix_string_out_params(&once.source).unwrap();
        assert!(twice.repointed.is_empty());
        assert_eq!(twice.already_correct, [GET_ERROR_STRING, BROWSE]);
        assert_eq!(twice.source, once.source);
    }

    #[test]
    fn idl_reader_finds_string_out_params() {
        let found = string_out_params_in_idl(FIXTURE_IDL).unwrap();
        assert_eq!(
            found,
            BTreeSet::from([GET_ERROR_STRING.to_string(), BROWSE.to_string()])
        );

        let idl = r#"
            // interface IFake : IUnknown { HRESULT X([out] LPWSTR* p); }
            cpp_quote("interface INotReal")
            interface IForward;
            [object, uuid(00000000-0000-0000-0000-000000000001)]
            interface IA : IUnknown
            {
                typedef [unique] IA* LPA;
                HRESULT Arrays([out, size_is(,*n)] LPWSTR** names, [out] DWORD* n);
                HRESULT InOnly([in] LPWSTR s, [in, size_is(n)] LPWSTR* items, [in] DWORD n);
                HRESULT Ole([in] REFCLSID c, [out] LPOLESTR * progId, [out] LPOLESTR* userType);
                HRESULT Reset(void);
            }
        "#;
        let found = string_out_params_in_idl(idl).unwrap();
        assert_eq!(
            found,
            BTreeSet::from([
                "IA::Ole(progId)".to_string(),
                "IA::Ole(userType)".to_string()
            ])
        );
    }

    #[test]
    fn real_idl_files_declare_the_documented_parameters() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"))
            .parent()
            .unwrap()
            .join("idl");
        let read = |f: &str| fs::read_to_string(root.join(f)).unwrap();
        let comn = string_out_params_in_idl(&read("opccomn.idl")).unwrap();
        let da = string_out_params_in_idl(&read("opcda.idl")).unwrap();
        let names = |s: &BTreeSet<String>| s.iter().cloned().collect::<Vec<_>>();
        assert_eq!(
            names(&comn),
            [
                "IOPCCommon::GetErrorString(ppString)",
                "IOPCServerList2::GetClassDetails(ppszProgID)",
                "IOPCServerList2::GetClassDetails(ppszUserType)",
                "IOPCServerList2::GetClassDetails(ppszVerIndProgID)",
                "IOPCServerList::GetClassDetails(ppszProgID)",
                "IOPCServerList::GetClassDetails(ppszUserType)",
            ]
        );
        assert_eq!(
            names(&da),
            [
                "IOPCBrowse::Browse(pszContinuationPoint)",
                "IOPCBrowseServerAddressSpace::GetItemID(szItemID)",
                "IOPCGroupStateMgt::GetState(ppName)",
                "IOPCServer::GetErrorString(ppString)",
            ]
        );
    }

    /// The machine-readable `// IID` and `// CATID` lines in the IDL headers agree with the
    /// `uuid(...)` attributes and the `DEFINE_GUID` lines, and list every interface.
    #[test]
    fn idl_header_lists_match_the_definitions() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"))
            .parent()
            .unwrap()
            .join("idl");
        for file in UNITS {
            let idl = fs::read_to_string(root.join(format!("{file}.idl"))).unwrap();
            let code = strip_comments(&idl);
            let mut listed = 0;
            for line in idl.lines() {
                let words: Vec<&str> = line.split_whitespace().collect();
                match words.as_slice() {
                    ["//", "IID", name, guid] => {
                        listed += 1;
                        let at = code
                            .find(&format!("interface {name} :"))
                            .unwrap_or_else(|| panic!("{name}"));
                        let uuid_at = code[..at].rfind("uuid(").unwrap();
                        let uuid = &code[uuid_at + 5..uuid_at + 41];
                        assert!(
                            uuid.eq_ignore_ascii_case(guid),
                            "{file}: {name} {guid} vs uuid({uuid})"
                        );
                    }
                    ["//", "CATID", name, guid] => {
                        let g: String = guid
                            .chars()
                            .filter(|c| *c != '-')
                            .collect::<String>()
                            .to_lowercase();
                        let mut args = vec![
                            format!("0x{}", &g[0..8]),
                            format!("0x{}", &g[8..12]),
                            format!("0x{}", &g[12..16]),
                        ];
                        args.extend((16..32).step_by(2).map(|i| format!("0x{}", &g[i..i + 2])));
                        let define = format!("DEFINE_GUID({name}, {});", args.join(", "));
                        assert!(idl.contains(&define), "{file}: missing `{define}`");
                    }
                    _ => {}
                }
            }
            let defined = code.matches("interface ").count();
            assert_eq!(
                listed, defined,
                "{file}: every interface needs an `// IID` line"
            );
        }
    }

    #[test]
    fn check_against_idl_accepts_only_the_declared_set() {
        let fix = fix_string_out_params(FIXTURE).unwrap();
        let declared = string_out_params_in_idl(FIXTURE_IDL).unwrap();
        check_against_idl(&fix, &declared).unwrap();

        let mut fewer = declared.clone();
        fewer.remove(BROWSE);
        let err = check_against_idl(&fix, &fewer).unwrap_err();
        assert!(
            err.contains("found but not declared") && err.contains(BROWSE),
            "{err}"
        );

        let mut more = declared;
        more.insert("IOPCCommon::Other(ppName)".into());
        let err = check_against_idl(&fix, &more).unwrap_err();
        assert!(err.contains("IOPCCommon::Other(ppName)"), "{err}");
    }

    fn fails_with(src: &str, needle: &str) {
        let err = fix_string_out_params(src).unwrap_err();
        assert!(
            err.contains(needle),
            "error `{err}` should mention `{needle}`"
        );
    }

    #[test]
    fn rejects_a_missing_array() {
        fails_with(
            &FIXTURE.replace("__MIDL_TypeFormatString", "__Other"),
            "__MIDL_TypeFormatString =` not found",
        );
        fails_with(
            &FIXTURE.replace("#define PROC_FORMAT_STRING_SIZE 253", ""),
            "PROC_FORMAT_STRING_SIZE",
        );
    }

    #[test]
    fn rejects_a_size_mismatch() {
        fails_with(
            &FIXTURE.replace(
                "#define TYPE_FORMAT_STRING_SIZE 57",
                "#define TYPE_FORMAT_STRING_SIZE 58",
            ),
            "TYPE_FORMAT_STRING_SIZE is 58",
        );
    }

    #[test]
    fn rejects_a_wrong_offset_annotation() {
        fails_with(
            &FIXTURE.replace("/* 32 (LPWSTR) */", "/* 34 (LPWSTR) */"),
            "byte offset is 32",
        );
    }

    #[test]
    fn rejects_unknown_tokens_and_comments() {
        fails_with(
            &FIXTURE.replacen("0x13, 0x8,", "0x13, FC_X,", 1),
            "unexpected token `FC_X`",
        );
        fails_with(
            &FIXTURE.replacen("/* 20 */", "/* twenty */", 1),
            "not an offset annotation",
        );
        fails_with(
            &FIXTURE.replacen("0x5c,\t/* FC_PAD */", "0x15c,\t/* FC_PAD */", 1),
            "out of range",
        );
    }

    #[test]
    fn rejects_a_string_out_param_without_its_fc_rp() {
        // The FC_RP in front of ppString's string pointer loses [allocated_on_stack].
        let src = FIXTURE.replace(
            "/* 28 (LPWSTR *) */\n        0x11, 0x14,",
            "/* 28 (LPWSTR *) */\n        0x11, 0x10,",
        );
        assert!(src.len() == FIXTURE.len() && src != FIXTURE);
        fails_with(
            &src,
            "IOPCCommon::GetErrorString(ppString): type offset 32 lands on a string pointer",
        );
    }

    #[test]
    fn rejects_a_changed_parameter_description() {
        // szName's type offset line is gone: the following annotations no longer match.
        let src = FIXTURE
            .replacen("        NdrFcShort(0x26),\t/* type offset = 38 */\n", "", 1)
            .replacen(
                "PROC_FORMAT_STRING_SIZE 253",
                "PROC_FORMAT_STRING_SIZE 251",
                1,
            );
        assert!(!src.contains("type offset = 38"));
        fails_with(
            &src,
            "`/* 196 (return value) */` but the byte offset is 194",
        );
        // The third line of a pointer parameter is not a type offset.
        let src = FIXTURE.replacen("/* type offset = 38 */", "/* offset = 38 */", 1);
        fails_with(
            &src,
            "IOPCCommon::SetClientName(szName): expected `NdrFcShort(..), /* type offset",
        );
        // Unknown annotation in the procedure format string.
        let src = FIXTURE.replacen("(return value)", "(something else)", 1);
        fails_with(&src, "unexpected annotation `32 (something else)`");
    }

    #[test]
    fn up_to_date_compares_modification_times() {
        let dir = std::env::temp_dir().join(format!("xtask-proxy-test-{}", std::process::id()));
        fs::create_dir_all(&dir).unwrap();
        let input = dir.join("in.idl");
        let output = dir.join("out.dll");
        fs::write(&input, "x").unwrap();
        assert!(
            !is_up_to_date(&output, std::slice::from_ref(&input)),
            "missing output"
        );
        fs::write(&output, "y").unwrap();
        let old = SystemTime::now() - std::time::Duration::from_secs(60);
        fs::File::options()
            .write(true)
            .open(&input)
            .unwrap()
            .set_modified(old)
            .unwrap();
        assert!(is_up_to_date(&output, std::slice::from_ref(&input)));
        assert!(
            !is_up_to_date(&output, &[input.clone(), dir.join("missing")]),
            "missing input"
        );
        fs::File::options()
            .write(true)
            .open(&output)
            .unwrap()
            .set_modified(old - std::time::Duration::from_secs(60))
            .unwrap();
        assert!(!is_up_to_date(&output, &[input]));
        fs::remove_dir_all(&dir).unwrap();
    }
}
