//! Files of secrets (private keys, the OPC UA users file) and their folders on Windows:
//! written with a protected DACL from their first byte, narrowed when they exist, and their
//! DACL read back, behind the portable `ctopc_runtime::secret_file` (the program installs
//! [`PLATFORM`] at its start).
//!
//! The descriptor is `ctopc_registration::security::secret_descriptor`: full control for
//! SYSTEM, Administrators, LOCAL SERVICE (the MSI's service account) and the account this
//! process runs as, nothing inherited from the parent; a folder's ACEs are inherited by what
//! is made in it. A new file is made with it (`CreateFileW` with the descriptor in its
//! security attributes: no moment where others may open it); an existing file or folder
//! gets it by `SetFileSecurityW` (DACL, protected), which needs no privilege from the
//! owner. Reading is `GetFileSecurityW` (owner and DACL, self-relative) into
//! `security::Descriptor`, judged by `security::secret_findings`.
//!
//! Under Wine the DACL is not kept: Wine maps it onto the Unix mode and answers a DACL
//! made from the mode (`platform::keeps_file_dacls`); what it can tell, who besides the
//! owner may read, is still judged.

use ctopc_registration::security::{self as sec, Descriptor, Sid};
use std::ffi::c_void;
use std::fs::File;
use std::io;
use std::os::windows::io::FromRawHandle as _;
use std::path::Path;
use windows::core::HSTRING;
use windows::Win32::Foundation::ERROR_FILE_EXISTS;
use windows::Win32::Foundation::{GENERIC_READ, GENERIC_WRITE, HANDLE, INVALID_HANDLE_VALUE};
use windows::Win32::Security::{
    GetFileSecurityW, SetFileSecurityW, DACL_SECURITY_INFORMATION, OWNER_SECURITY_INFORMATION,
    PROTECTED_DACL_SECURITY_INFORMATION, PSECURITY_DESCRIPTOR, SECURITY_ATTRIBUTES,
    UNPROTECTED_DACL_SECURITY_INFORMATION,
};

// `CreateFileW`, declared here rather than through the `windows` crate's
// Win32_Storage_FileSystem feature (which would rebuild that crate for one function).
windows_core::link!("kernel32.dll" "system" fn CreateFileW(
    name: windows_core::PCWSTR,
    access: u32,
    share: u32,
    attributes: *const SECURITY_ATTRIBUTES,
    disposition: u32,
    flags: u32,
    template: HANDLE,
) -> HANDLE);

const FILE_SHARE_READ: u32 = 0x1;
const CREATE_NEW: u32 = 1;
const FILE_ATTRIBUTE_NORMAL: u32 = 0x80;

/// What `ctopc_runtime::secret_file` calls on Windows.
pub const PLATFORM: ctopc_runtime::secret_file::Platform = ctopc_runtime::secret_file::Platform {
    create,
    narrow,
    finding,
};

/// A descriptor's self-relative bytes in an 8-byte aligned buffer (what the Win32 calls
/// read it from).
struct Aligned(Vec<u64>);

impl Aligned {
    fn new(bytes: &[u8]) -> Aligned {
        let mut buf = vec![0u64; bytes.len().div_ceil(8)];
        // SAFETY: `buf` holds at least `bytes.len()` bytes; the two do not overlap.
        unsafe {
            std::ptr::copy_nonoverlapping(bytes.as_ptr(), buf.as_mut_ptr().cast(), bytes.len())
        };
        Aligned(buf)
    }

    fn as_psd(&self) -> PSECURITY_DESCRIPTOR {
        PSECURITY_DESCRIPTOR(self.0.as_ptr() as *mut c_void)
    }
}

/// The account this process runs as.
pub fn process_user() -> io::Result<Sid> {
    let bytes = crate::com::caller::process_user_sid().map_err(io::Error::other)?;
    Sid::from_bytes(&bytes).ok_or_else(|| io::Error::other("the process's user SID is malformed"))
}

/// The descriptor this process writes a file (`folder`: a folder) of secrets with.
pub fn descriptor_to_write(folder: bool) -> io::Result<Descriptor> {
    Ok(sec::secret_descriptor(&process_user()?, folder))
}

/// Makes `path` a new file with the secrets' DACL, open for writing; an existing file is
/// narrowed ([`narrow`]) and opened truncated.
pub fn create(path: &Path) -> io::Result<File> {
    let sd = Aligned::new(&descriptor_to_write(false)?.to_bytes());
    let attributes = SECURITY_ATTRIBUTES {
        nLength: std::mem::size_of::<SECURITY_ATTRIBUTES>() as u32,
        lpSecurityDescriptor: sd.as_psd().0,
        bInheritHandle: false.into(),
    };
    let name = HSTRING::from(path.as_os_str());
    // SAFETY: the name is a live NUL-terminated HSTRING; the attributes and the
    // descriptor they point to (a checked self-relative one, aligned) live across the call.
    let h = unsafe {
        CreateFileW(
            windows_core::PCWSTR(name.as_ptr()),
            GENERIC_READ.0 | GENERIC_WRITE.0,
            FILE_SHARE_READ,
            &attributes,
            CREATE_NEW,
            FILE_ATTRIBUTE_NORMAL,
            HANDLE::default(),
        )
    };
    if h != INVALID_HANDLE_VALUE && !h.is_invalid() {
        // SAFETY: a handle CreateFileW just opened and nobody else owns: the File owns it.
        return Ok(unsafe { File::from_raw_handle(h.0) });
    }
    let e = io::Error::last_os_error();
    if e.raw_os_error() != Some(ERROR_FILE_EXISTS.0 as i32) {
        return Err(e);
    }
    narrow(path, false)?;
    std::fs::OpenOptions::new()
        .write(true)
        .truncate(true)
        .open(path)
}

/// Gives the existing file or folder `path` the secrets' DACL (protected).
pub fn narrow(path: &Path, folder: bool) -> io::Result<()> {
    set_dacl(path, &descriptor_to_write(folder)?)
}

/// Sets the DACL of `d` on `path` (protected or not, as `d` says; owner and group as
/// they are).
pub fn set_dacl(path: &Path, d: &Descriptor) -> io::Result<()> {
    let sd = Aligned::new(&d.to_bytes());
    let what = if d.protected {
        DACL_SECURITY_INFORMATION | PROTECTED_DACL_SECURITY_INFORMATION
    } else {
        DACL_SECURITY_INFORMATION | UNPROTECTED_DACL_SECURITY_INFORMATION
    };
    // SAFETY: the name is a live HSTRING, the descriptor a checked self-relative one,
    // aligned and alive across the call.
    let ok = unsafe { SetFileSecurityW(&HSTRING::from(path.as_os_str()), what, sd.as_psd()) };
    if ok.as_bool() {
        Ok(())
    } else {
        Err(io::Error::last_os_error())
    }
}

/// The owner and DACL of `path` (`GetFileSecurityW`, self-relative), parsed (under Wine,
/// which keeps no file DACL, as `platform::file_descriptor_as_kept` says).
pub fn read(path: &Path) -> io::Result<Descriptor> {
    let name = HSTRING::from(path.as_os_str());
    let what = (OWNER_SECURITY_INFORMATION | DACL_SECURITY_INFORMATION).0;
    let mut needed = 0u32;
    // SAFETY: a size query: no buffer, `needed` a live out-parameter.
    let _ = unsafe { GetFileSecurityW(&name, what, None, 0, &mut needed) };
    if needed == 0 {
        return Err(io::Error::last_os_error());
    }
    if needed > 64 * 1024 {
        return Err(io::Error::other(format!(
            "its security descriptor is {needed} bytes"
        )));
    }
    let mut buf = vec![0u64; (needed as usize).div_ceil(8)];
    // SAFETY: `buf` has room for `needed` bytes, aligned; `needed` a live out-parameter.
    let ok = unsafe {
        GetFileSecurityW(
            &name,
            what,
            Some(PSECURITY_DESCRIPTOR(buf.as_mut_ptr().cast())),
            needed,
            &mut needed,
        )
    };
    if !ok.as_bool() {
        return Err(io::Error::last_os_error());
    }
    // SAFETY: `buf` holds `buf.len() * 8` initialised bytes.
    let bytes = unsafe { std::slice::from_raw_parts(buf.as_ptr() as *const u8, buf.len() * 8) };
    Descriptor::from_bytes(bytes)
        .map(crate::com::platform::file_descriptor_as_kept)
        .ok_or_else(|| io::Error::other("GetFileSecurityW answered no self-relative descriptor"))
}

/// What is weaker on `path` than a secret allows (`security::secret_findings`, also
/// allowing `also`: the service's account), in one sentence; `None` when it is private or
/// absent.
pub fn findings(path: &Path, also: &[Sid]) -> Option<String> {
    if !path.exists() {
        return None;
    }
    let d = match read(path) {
        Ok(d) => d,
        Err(e) => return Some(format!("its DACL cannot be read: {e}")),
    };
    let f = sec::secret_findings(&d, also);
    (!f.is_empty()).then(|| f.join("; "))
}

/// The runtime's check: what this process wrote may also be this process's.
fn finding(path: &Path) -> Option<String> {
    let me: Vec<Sid> = process_user().into_iter().collect();
    findings(path, &me)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ctopc_registration::security::{Ace, EVERYONE, FILE_ALL_ACCESS, SECRET_HOLDERS};
    use std::io::Write as _;

    /// The ACEs of a descriptor as (SID, flags, mask).
    fn aces(d: &Descriptor) -> Vec<(String, u8, u32)> {
        d.dacl
            .iter()
            .flatten()
            .map(|a| (a.sid.to_string(), a.flags, a.mask))
            .collect()
    }

    fn holders(flags: u8) -> Vec<(String, u8, u32)> {
        let mut h: Vec<(String, u8, u32)> = SECRET_HOLDERS
            .iter()
            .map(|s| (s.to_string(), flags, FILE_ALL_ACCESS))
            .collect();
        h.push((process_user().unwrap().to_string(), flags, FILE_ALL_ACCESS));
        h
    }

    /// Under Wine (on a file system with extended attributes) and on Windows: the folder
    /// and the file are read back with exactly the DACL written, protected; a file opened
    /// to Everyone is found, and writing it again narrows it.
    #[test]
    fn secrets_are_written_with_a_protected_dacl_and_an_open_one_is_found() {
        let dir = std::env::temp_dir().join(format!("ctopc-secret-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        narrow(&dir, true).unwrap();
        let me = process_user().unwrap();
        // Exactly the DACL written where the platform keeps it; under Wine (a DACL made
        // from the Unix mode) nobody but SYSTEM and the owner.
        let kept = |d: &Descriptor, flags: u8| {
            if crate::com::platform::keeps_file_dacls() {
                assert!(d.protected, "{}", d.sddl());
                assert_eq!(aces(d), holders(flags), "{}", d.sddl());
            } else {
                let system = Sid::parse(sec::SYSTEM).unwrap();
                for a in d.dacl.iter().flatten() {
                    assert!(a.sid == system || a.sid == me, "{}", d.sddl());
                }
            }
        };
        let d = read(&dir).unwrap();
        kept(&d, 0x3);
        assert_eq!(findings(&dir, &[]), None);

        let key = dir.join("private.pem");
        let mut f = create(&key).unwrap();
        f.write_all(b"secret").unwrap();
        drop(f);
        assert_eq!(std::fs::read(&key).unwrap(), b"secret");
        let d = read(&key).unwrap();
        kept(&d, 0);
        assert_eq!(d.owner, Some(me.clone()), "{}", d.sddl());
        assert_eq!(findings(&key, &[]), None);

        // Opened to Everyone: found; written again through the runtime: private again.
        let mut open = d.clone();
        open.dacl
            .get_or_insert_with(Vec::new)
            .push(Ace::allow(Sid::parse(EVERYONE).unwrap(), 0x0012_00A9));
        open.protected = false;
        set_dacl(&key, &open).unwrap();
        let found = findings(&key, &[]).unwrap_or_default();
        assert!(found.contains("Everyone (S-1-1-0) may read it"), "{found}");
        ctopc_runtime::secret_file::install(PLATFORM);
        assert!(ctopc_runtime::secret_file::warn_if_exposed(&key, "the key"));
        ctopc_runtime::secret_file::write(&key, b"new").unwrap();
        assert_eq!(std::fs::read(&key).unwrap(), b"new");
        kept(&read(&key).unwrap(), 0);
        assert_eq!(ctopc_runtime::secret_file::finding(&key), None);
        assert_eq!(findings(&dir.join("absent"), &[]), None);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
