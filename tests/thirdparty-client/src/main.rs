//! An OPC DA client we did not write talks to ServerCTOPC.App: opc_da's `ServerTrait` and
//! `CommonTrait` over opc_da_bindings' IOPCServer/IOPCCommon (generated from the OPC
//! Foundation's IDL). Prints one line per check and `N passed, M failed`; exits non-zero
//! on any failure.

#[cfg(windows)]
fn main() -> std::process::ExitCode {
    use opc_da::client::{v2::Group, CommonTrait, ServerTrait};
    use windows::Win32::System::Com::{CLSIDFromProgID, CoCreateInstance, CoInitializeEx, CLSCTX_LOCAL_SERVER, COINIT_MULTITHREADED};

    struct ThirdParty {
        server: opc_da_bindings::IOPCServer,
        common: opc_comn_bindings::IOPCCommon,
    }
    impl ServerTrait<Group> for ThirdParty {
        fn interface(&self) -> windows::core::Result<&opc_da_bindings::IOPCServer> {
            Ok(&self.server)
        }
    }
    impl CommonTrait for ThirdParty {
        fn interface(&self) -> windows::core::Result<&opc_comn_bindings::IOPCCommon> {
            Ok(&self.common)
        }
    }

    let mut passed = 0;
    let mut failed = 0;
    let mut check = |name: &str, ok: bool, detail: String| {
        if ok {
            passed += 1;
            println!("ok   {name}: {detail}");
        } else {
            failed += 1;
            println!("FAIL {name}: {detail}");
        }
    };

    let run = || -> windows::core::Result<ThirdParty> {
        unsafe { CoInitializeEx(None, COINIT_MULTITHREADED).ok()? };
        let clsid = unsafe { CLSIDFromProgID(windows::core::w!("ServerCTOPC.App"))? };
        let unknown: windows::core::IUnknown = unsafe { CoCreateInstance(&clsid, None, CLSCTX_LOCAL_SERVER)? };
        use windows::core::Interface;
        Ok(ThirdParty { server: unknown.cast()?, common: unknown.cast()? })
    };
    let client = match run() {
        Ok(c) => c,
        Err(e) => {
            println!("FAIL connect: {e:?}");
            println!("thirdparty-client: 0 passed, 1 failed");
            return std::process::ExitCode::FAILURE;
        }
    };
    match client.get_status() {
        Ok(status) => match status.ok() {
            Ok(s) => {
                let vendor = unsafe { s.szVendorInfo.to_string() }.unwrap_or_default();
                let ft = |f: windows::Win32::Foundation::FILETIME| ((f.dwHighDateTime as u64) << 32) | f.dwLowDateTime as u64;
                check("GetStatus vendor", vendor.starts_with("ServerCTOPC"), vendor.clone());
                check("GetStatus times", ft(s.ftStartTime) > 0 && ft(s.ftStartTime) <= ft(s.ftCurrentTime), format!("start {} current {}", ft(s.ftStartTime), ft(s.ftCurrentTime)));
                check("GetStatus state", (1..=6).contains(&s.dwServerState.0), format!("{}", s.dwServerState.0));
                check("GetStatus version", s.wMajorVersion == 0 && s.wMinorVersion >= 1, format!("{}.{}.{}", s.wMajorVersion, s.wMinorVersion, s.wBuildNumber));
            }
            Err(e) => check("GetStatus", false, format!("NULL status: {e:?}")),
        },
        Err(e) => check("GetStatus", false, format!("{e:?}")),
    }
    match client.query_available_locale_ids() {
        Ok(ids) => {
            let ids = ids.as_slice().to_vec();
            check("QueryAvailableLocaleIDs", ids.contains(&0x0415) && ids.contains(&0x0409), format!("{ids:x?}"));
        }
        Err(e) => check("QueryAvailableLocaleIDs", false, format!("{e:?}")),
    }
    let lcid = client.set_locale_id(0x0415).and_then(|_| client.get_locale_id());
    check("SetLocaleID/GetLocaleID", matches!(lcid, Ok(0x0415)), format!("{lcid:x?}"));
    let text = client.get_error_string(windows::core::HRESULT(0xC0040007u32 as i32));
    check("GetErrorString", matches!(&text, Ok(t) if !t.is_empty()), format!("{text:?}"));
    check("SetClientName", client.set_client_name("opc_da-client żółć").is_ok(), String::new());

    println!("thirdparty-client: {passed} passed, {failed} failed");
    if failed == 0 { std::process::ExitCode::SUCCESS } else { std::process::ExitCode::FAILURE }
}

#[cfg(not(windows))]
fn main() {
    eprintln!("thirdparty-client is a Windows program; `cargo xtask test` builds and runs it under Wine");
    std::process::exit(1);
}
