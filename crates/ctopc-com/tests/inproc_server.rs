//! IOPCServer and IOPCCommon of the server object, in process (no proxy): every argument
//! branch with its exact HRESULT, out-parameters cleared on failure, and each method's
//! success path. The harness is `common/mod.rs`.
#![cfg(windows)]

mod common;

use common::*;
use ctopc_com::interfaces::*;

#[test]
fn the_class_factory_makes_a_server_object_with_the_opc_interfaces() {
    let unk = new_server();
    assert!(unk.cast::<IOPCServer>().is_ok());
    assert!(unk.cast::<IOPCCommon>().is_ok());
    assert!(unk.cast::<IOPCBrowseServerAddressSpace>().is_ok());
    assert!(unk.cast::<IOPCItemProperties>().is_ok());
    assert!(unk.cast::<IOPCBrowse>().is_ok());
    assert!(unk.cast::<IOPCItemIO>().is_ok());
    assert!(unk
        .cast::<windows::Win32::System::Com::IConnectionPointContainer>()
        .is_ok());
}

#[test]
fn the_group_helper_adds_a_group() {
    let (server, g) = server_with_group("harness");
    assert_eq!(g.code, S_OK);
    assert_ne!(g.server_handle, 0);
    assert_eq!(g.revised_rate, 1000);
    // SAFETY: a valid handle of this client's group.
    assert_eq!(
        unsafe { server.RemoveGroup(g.server_handle, true.into()) },
        S_OK
    );
}
