//! The two Windows bitnesses the project builds for: x64 (the server, the 64-bit
//! proxy/stub and clients) and x86 (the 32-bit proxy/stub, opcdiag and the e2e tests as a
//! 32-bit OPC client). One prefix serves both: a win64 Wine prefix runs 32-bit
//! programs through WoW64 from `syswow64`.

use std::path::{Path, PathBuf};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Arch {
    X64,
    X86,
}

impl Arch {
    pub const ALL: [Arch; 2] = [Arch::X64, Arch::X86];

    /// The Rust target triple.
    pub fn target(self) -> &'static str {
        match self {
            Arch::X64 => "x86_64-pc-windows-gnu",
            Arch::X86 => "i686-pc-windows-gnu",
        }
    }

    /// The mingw C compiler (also the Rust linker, .cargo/config.toml).
    pub fn gcc(self) -> &'static str {
        match self {
            Arch::X64 => "x86_64-w64-mingw32-gcc",
            Arch::X86 => "i686-w64-mingw32-gcc",
        }
    }

    pub fn widl(self) -> &'static str {
        match self {
            Arch::X64 => "x86_64-w64-mingw32-widl",
            Arch::X86 => "i686-w64-mingw32-widl",
        }
    }

    /// widl's pointer-size switch.
    pub fn widl_m(self) -> &'static str {
        match self {
            Arch::X64 => "-m64",
            Arch::X86 => "-m32",
        }
    }

    /// The prefix's system folder for DLLs of this bitness (Windows' own names: 32-bit
    /// system DLLs of a 64-bit Windows live in SysWOW64).
    pub fn system_dir(self) -> &'static str {
        match self {
            Arch::X64 => "system32",
            Arch::X86 => "syswow64",
        }
    }

    /// Wine's loader for this bitness (Debian has no /usr/bin/wine64: the loaders are in
    /// /usr/lib/wine).
    pub fn loader(self) -> &'static str {
        match self {
            Arch::X64 => "/usr/lib/wine/wine64",
            Arch::X86 => "/usr/lib/wine/wine",
        }
    }

    /// `target/<triple>/release` under `root`.
    pub fn release_dir(self, root: &Path) -> PathBuf {
        root.join("target").join(self.target()).join("release")
    }

    /// The folder name in the distribution and the install folder: none for x64 (the
    /// server's bitness), `x86` for 32-bit files.
    pub fn dist_subdir(self) -> Option<&'static str> {
        match self {
            Arch::X64 => None,
            Arch::X86 => Some("x86"),
        }
    }
}
