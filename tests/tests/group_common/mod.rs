//! Helpers shared by the group tests (group_items, group_state, group_callbacks): a group
//! made through IOPCServer::AddGroup, and the OnDataChange calls of opc-client's
//! recording sink read as [`Change`]s.
#![allow(dead_code)]

use e2e_tests::interfaces::*;
use opc_client::sink::Callback;
use opc_client::{ItemDef, OpcGroup, Server};
use std::time::{Duration, Instant};
use windows::core::{IUnknown, Interface, BOOL, HRESULT, HSTRING, PCWSTR};
use windows::Win32::System::Com::{IConnectionPoint, IConnectionPointContainer};

pub const VT_EMPTY: u16 = 0;
pub const VT_I2: u16 = 2;
pub const VT_I4: u16 = 3;
pub const VT_R4: u16 = 4;
pub const VT_R8: u16 = 5;
pub const VT_BSTR: u16 = 8;
pub const VT_DISPATCH: u16 = 9;
pub const VT_ARRAY: u16 = 0x2000;

/// A group made with IOPCServer::AddGroup (update rate 1000 ms, English, no deadband).
pub struct G {
    pub group: OpcGroup,
    pub server_handle: u32,
    pub revised_rate: u32,
}

impl std::ops::Deref for G {
    type Target = OpcGroup;
    fn deref(&self) -> &OpcGroup {
        &self.group
    }
}

/// IOPCServer::AddGroup, asking for IUnknown.
pub fn try_add_group(
    server: &Server,
    name: &str,
    active: bool,
    rate: u32,
    client: u32,
) -> windows::core::Result<G> {
    let name = HSTRING::from(name);
    let (mut handle, mut revised) = (0u32, 0u32);
    let mut unk: Option<IUnknown> = None;
    let deadband = 0.0f32;
    let bias = 0i32;
    // SAFETY: valid string, in-pointers and out-pointers for the call.
    let hr = unsafe {
        server.server.AddGroup(
            PCWSTR(name.as_ptr()),
            BOOL::from(active),
            rate,
            client,
            &bias,
            &deadband,
            0x0409,
            &mut handle,
            &mut revised,
            &IUnknown::IID,
            &mut unk,
        )
    };
    hr.ok()?;
    let unknown =
        unk.ok_or_else(|| windows::core::Error::from(windows::Win32::Foundation::E_POINTER))?;
    Ok(G {
        group: OpcGroup::from_unknown(unknown)?,
        server_handle: handle,
        revised_rate: revised,
    })
}

pub fn add_group(server: &Server, name: &str, active: bool, client: u32) -> G {
    try_add_group(server, name, active, 1000, client).expect("AddGroup")
}

/// AddItems that must succeed for every item: the server handles.
pub fn add_ok(g: &OpcGroup, items: &[ItemDef]) -> Vec<u32> {
    let (hr, out) = g.add_items(items).expect("AddItems");
    assert_eq!(hr, HRESULT(0), "AddItems: {out:x?}");
    out.iter().map(|o| o.server_handle).collect()
}

pub fn item(id: &str, client: u32) -> ItemDef {
    ItemDef::new(id, client)
}

pub fn item_in(id: &str, path: &str, client: u32) -> ItemDef {
    ItemDef {
        access_path: path.into(),
        ..ItemDef::new(id, client)
    }
}

pub fn item_typed(id: &str, client: u32, vt: u16) -> ItemDef {
    ItemDef {
        requested_type: vt,
        ..ItemDef::new(id, client)
    }
}

pub fn inactive(id: &str, client: u32) -> ItemDef {
    ItemDef {
        active: false,
        ..ItemDef::new(id, client)
    }
}

/// The group's IOPCDataCallback connection point.
pub fn data_point(g: &OpcGroup) -> IConnectionPoint {
    let cpc: IConnectionPointContainer = g.unknown.cast().expect("IConnectionPointContainer");
    // SAFETY: valid IID.
    unsafe { cpc.FindConnectionPoint(&IOPCDataCallback::IID) }
        .expect("FindConnectionPoint(IOPCDataCallback)")
}

// ---- the recording ---------------------------------------------------------------------

pub use opc_client::sink::Recording;

/// One OnDataChange, as the group tests read it from a [`Recording`].
#[derive(Debug, Clone, PartialEq)]
pub struct Change {
    pub transaction: u32,
    pub group: u32,
    pub master_quality: HRESULT,
    pub master_error: HRESULT,
    /// (client handle, value, quality, error)
    pub items: Vec<(u32, ctopc_core::Value, u16, HRESULT)>,
    pub at: Instant,
}

/// The OnDataChange calls of a recording, in order.
pub trait Changes {
    fn changes(&self) -> Vec<Change>;
    /// How many OnDataChange calls came.
    fn count(&self) -> usize;
    /// Waits at most `limit` for `n` OnDataChange calls that `pred` accepts: those that
    /// came.
    fn wait(&self, limit: Duration, n: usize, pred: impl Fn(&Change) -> bool) -> Vec<Change>;
}

fn change(at: Instant, c: Callback) -> Option<Change> {
    match c {
        Callback::DataChange {
            transaction,
            group,
            master_quality,
            master_error,
            items,
        } => Some(Change {
            transaction,
            group,
            master_quality,
            master_error,
            items: items
                .into_iter()
                .map(|i| (i.client_handle, i.value, i.quality, i.error))
                .collect(),
            at,
        }),
        _ => None,
    }
}

impl Changes for Recording {
    fn changes(&self) -> Vec<Change> {
        self.timed()
            .into_iter()
            .filter_map(|(at, c)| change(at, c))
            .collect()
    }

    fn count(&self) -> usize {
        self.changes().len()
    }

    fn wait(&self, limit: Duration, n: usize, pred: impl Fn(&Change) -> bool) -> Vec<Change> {
        let matching = |log: &[(Instant, Callback)]| -> Vec<Change> {
            log.iter()
                .filter_map(|(at, c)| change(*at, c.clone()))
                .filter(|c| pred(c))
                .collect()
        };
        self.wait_until(limit, |log, _| {
            let found = matching(log);
            (found.len() >= n).then_some(found)
        })
        .unwrap_or_else(|| matching(&self.timed()))
    }
}

/// Advises `sink` on the group's IOPCDataCallback point: the cookie.
pub fn advise(g: &OpcGroup, sink: &IOPCDataCallback) -> windows::core::Result<u32> {
    let cp = data_point(g);
    // SAFETY: a valid interface pointer.
    unsafe { cp.Advise(&sink.cast::<IUnknown>()?) }
}

pub fn unadvise(g: &OpcGroup, cookie: u32) -> windows::core::Result<()> {
    let cp = data_point(g);
    // SAFETY: plain value.
    unsafe { cp.Unadvise(cookie) }
}
