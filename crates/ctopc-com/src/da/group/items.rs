//! The items of a group: IOPCItemMgt (with the IEnumOPCItemAttributes enumerator),
//! IOPCItemDeadbandMgt and IOPCItemSamplingMgt.
//!
//! AddItems of many items is one pass: the item IDs and access paths are decoded into one
//! string buffer, the output arrays are allocated once before the core call (so nothing
//! can fail after items were added), and the core adds every item under one lock.

use super::Group_Impl;
use crate::com::abi::{self, in_array, OutArray, OwnedArray};
use crate::com::enums::{check_next, Cursor};
use crate::com::interfaces::*;
use crate::com::lifetime::ObjectGuard;
use crate::com::{error, variant};
use ctopc_core::limits::{self, TextLimit};
use ctopc_core::metrics::Method;
use ctopc_core::model::{ItemAttributes, ItemDefinition, ItemResult};
use ctopc_core::namespace::EuInfo;
use ctopc_core::value::ArrayValue;
use ctopc_core::{OpcError, Value, VarType};
use std::ops::Range;
use windows::core::{implement, IUnknown, Interface, BOOL, GUID, HRESULT, PWSTR};
use windows::Win32::Foundation::{E_INVALIDARG, E_NOINTERFACE, E_OUTOFMEMORY, S_FALSE, S_OK};
use windows::Win32::System::Variant::{VARENUM, VARIANT};

// ---------------------------------------------------------------------------------------
// OPCITEMDEF decoding
// ---------------------------------------------------------------------------------------

/// Appends the UTF-16 string `p` to `buf`; its range there, or None for invalid UTF-16
/// or a text longer than `limit` (logged, not decoded).
fn push_wstr(buf: &mut String, p: PWSTR, limit: TextLimit) -> Option<Range<usize>> {
    let start = buf.len();
    if p.is_null() {
        return Some(start..start);
    }
    // SAFETY: a non-null string of an OPCITEMDEF is a NUL-terminated UTF-16 string that
    // lives for the call.
    let wide = unsafe { p.as_wide() };
    if limit.check_units(wide.len()).is_err() {
        tracing::warn!(
            "a client {} of {} UTF-16 units, over the limit of {}: {}",
            limit.what,
            wide.len(),
            limit.max_units,
            limit.error.symbol()
        );
        return None;
    }
    for c in char::decode_utf16(wide.iter().copied()) {
        match c {
            Ok(c) => buf.push(c),
            Err(_) => {
                buf.truncate(start);
                return None;
            }
        }
    }
    Some(start..buf.len())
}

/// The item definitions of an AddItems/ValidateItems call: per item, the decoded
/// (item ID, access path) ranges in `buf`, or the error the item fails with before the
/// core sees it (NULL, invalid or too long item ID: OPC_E_INVALIDITEMID; invalid or too
/// long access path: OPC_E_UNKNOWNPATH; limits in [`ctopc_core::limits`]).
struct Defs {
    buf: String,
    items: Vec<Result<Decoded, OpcError>>,
}

/// The ranges of an item's ID and access path in [`Defs::buf`].
type Decoded = (Range<usize>, Range<usize>);

impl Defs {
    fn decode(defs: &[OPCITEMDEF]) -> Defs {
        let mut buf = String::with_capacity(defs.len() * 16);
        let mut items = Vec::with_capacity(defs.len());
        for d in defs {
            let item = if d.szItemID.is_null() {
                Err(OpcError::InvalidItemId)
            } else {
                match (
                    push_wstr(&mut buf, d.szItemID, limits::ITEM_ID),
                    push_wstr(&mut buf, d.szAccessPath, limits::ACCESS_PATH),
                ) {
                    (Some(id), Some(path)) => Ok((id, path)),
                    (None, _) => Err(OpcError::InvalidItemId),
                    (_, None) => Err(OpcError::UnknownPath),
                }
            };
            items.push(item);
        }
        Defs { buf, items }
    }

    /// The definitions the core gets (only the items that decoded).
    fn core_defs<'a>(&'a self, defs: &[OPCITEMDEF]) -> Vec<ItemDefinition<'a>> {
        let mut out = Vec::with_capacity(defs.len());
        for (d, item) in defs.iter().zip(&self.items) {
            if let Ok((id, path)) = item {
                out.push(ItemDefinition {
                    item_id: &self.buf[id.clone()],
                    access_path: &self.buf[path.clone()],
                    active: d.bActive.as_bool(),
                    client_handle: d.hClient,
                    requested_type: VarType(d.vtRequestedDataType.0),
                });
            }
        }
        out
    }

    /// Merges the core's results (one per decoded item) with the decoding errors, in the
    /// order of the call.
    fn merge<R>(&self, core: Vec<Result<R, OpcError>>) -> Vec<Result<R, OpcError>> {
        if core.len() == self.items.len() {
            return core;
        }
        let mut core = core.into_iter();
        self.items
            .iter()
            .map(|item| match item {
                Ok(_) => core.next().unwrap_or(Err(OpcError::Fail)),
                Err(e) => Err(*e),
            })
            .collect()
    }
}

fn item_result(r: Result<ItemResult, OpcError>) -> (OPCITEMRESULT, HRESULT) {
    match r {
        Ok(r) => (
            OPCITEMRESULT {
                hServer: r.server_handle,
                vtCanonicalDataType: VARENUM(r.canonical_type.0),
                wReserved: 0,
                dwAccessRights: r.access_rights,
                dwBlobSize: 0,
                pBlob: std::ptr::null_mut(),
            },
            S_OK,
        ),
        Err(e) => (OPCITEMRESULT::default(), error::hresult(e)),
    }
}

fn plain<V: Default>(r: Result<V, OpcError>) -> (V, HRESULT) {
    match r {
        Ok(v) => (v, S_OK),
        Err(e) => (V::default(), error::hresult(e)),
    }
}

/// Returns early from a COM method with the HRESULT of a failed argument check.
macro_rules! check {
    ($e:expr) => {
        match $e {
            Ok(v) => v,
            Err(e) => return e.code(),
        }
    };
}

// ---------------------------------------------------------------------------------------
// IOPCItemMgt
// ---------------------------------------------------------------------------------------

impl IOPCItemMgt_Impl for Group_Impl {
    unsafe fn AddItems(
        &self,
        dwcount: u32,
        pitemarray: *const OPCITEMDEF,
        ppaddresults: *mut *mut OPCITEMRESULT,
        pperrors: *mut *mut HRESULT,
    ) -> HRESULT {
        let _t = self.ctx.timed(Method::AddItems);
        // SAFETY: this method's [out] parameters.
        unsafe { abi::clear_outs((ppaddresults, pperrors)) };
        let results = check!(OutArray::new(ppaddresults));
        let errors = check!(OutArray::new(pperrors));
        let defs = check!(in_array(pitemarray, dwcount));
        let decoded = Defs::decode(defs);
        let core_defs = decoded.core_defs(defs);
        self.per_item_values(
            defs.len(),
            results,
            errors,
            |e, now, g| {
                let core = if core_defs.is_empty() {
                    Vec::new()
                } else {
                    e.add_items(now, g, &core_defs)?
                };
                Ok(decoded.merge(core))
            },
            item_result,
        )
    }

    /// `bBlobUpdate` is ignored: this server uses no blobs (pBlob NULL, dwBlobSize 0).
    unsafe fn ValidateItems(
        &self,
        dwcount: u32,
        pitemarray: *const OPCITEMDEF,
        _bblobupdate: BOOL,
        ppvalidationresults: *mut *mut OPCITEMRESULT,
        pperrors: *mut *mut HRESULT,
    ) -> HRESULT {
        // SAFETY: this method's [out] parameters.
        unsafe { abi::clear_outs((ppvalidationresults, pperrors)) };
        let results = check!(OutArray::new(ppvalidationresults));
        let errors = check!(OutArray::new(pperrors));
        let defs = check!(in_array(pitemarray, dwcount));
        let decoded = Defs::decode(defs);
        let core_defs = decoded.core_defs(defs);
        self.per_item_values(
            defs.len(),
            results,
            errors,
            |e, _, g| {
                let core = if core_defs.is_empty() {
                    Vec::new()
                } else {
                    e.validate_items(g, &core_defs)?
                };
                Ok(decoded.merge(core))
            },
            item_result,
        )
    }

    unsafe fn RemoveItems(
        &self,
        dwcount: u32,
        phserver: *const OPCHANDLE,
        pperrors: *mut *mut HRESULT,
    ) -> HRESULT {
        let _t = self.ctx.timed(Method::RemoveItems);
        let errors = check!(OutArray::new(pperrors));
        let handles = check!(in_array(phserver, dwcount));
        self.per_item(handles.len(), errors, |e, now, g| {
            e.remove_items(now, g, handles)
        })
    }

    unsafe fn SetActiveState(
        &self,
        dwcount: u32,
        phserver: *const OPCHANDLE,
        bactive: BOOL,
        pperrors: *mut *mut HRESULT,
    ) -> HRESULT {
        let errors = check!(OutArray::new(pperrors));
        let handles = check!(in_array(phserver, dwcount));
        let active = bactive.as_bool();
        self.per_item(handles.len(), errors, |e, now, g| {
            e.set_active_state(now, g, handles, active)
        })
    }

    unsafe fn SetClientHandles(
        &self,
        dwcount: u32,
        phserver: *const OPCHANDLE,
        phclient: *const OPCHANDLE,
        pperrors: *mut *mut HRESULT,
    ) -> HRESULT {
        let errors = check!(OutArray::new(pperrors));
        let handles = check!(in_array(phserver, dwcount));
        let clients = check!(in_array(phclient, dwcount));
        let pairs: Vec<(u32, u32)> = handles
            .iter()
            .copied()
            .zip(clients.iter().copied())
            .collect();
        self.per_item(handles.len(), errors, |e, _, g| {
            e.set_client_handles(g, &pairs)
        })
    }

    unsafe fn SetDatatypes(
        &self,
        dwcount: u32,
        phserver: *const OPCHANDLE,
        prequesteddatatypes: *const VARTYPE,
        pperrors: *mut *mut HRESULT,
    ) -> HRESULT {
        let errors = check!(OutArray::new(pperrors));
        let handles = check!(in_array(phserver, dwcount));
        let types = check!(in_array(prequesteddatatypes, dwcount));
        let pairs: Vec<(u32, VarType)> = handles
            .iter()
            .copied()
            .zip(types.iter().map(|t| VarType(t.0)))
            .collect();
        self.per_item(handles.len(), errors, |e, _, g| e.set_datatypes(g, &pairs))
    }

    /// Only IID_IEnumOPCItemAttributes (E_NOINTERFACE otherwise); S_FALSE with an empty
    /// enumerator when the group has no items.
    unsafe fn CreateEnumerator(&self, riid: *const GUID, ppunk: *mut Option<IUnknown>) -> HRESULT {
        // SAFETY: this method's [out] interface pointer.
        unsafe { abi::clear_outs((ppunk,)) };
        if riid.is_null() || ppunk.is_null() {
            return E_INVALIDARG;
        }
        // SAFETY: checked non-null; an [in] REFIID.
        let iid = unsafe { *riid };
        if iid != IEnumOPCItemAttributes::IID {
            return E_NOINTERFACE;
        }
        let items = match self.engine(|e, _, g| e.item_attributes(g)) {
            Ok(items) => items,
            Err(e) => return error::hresult(e),
        };
        let empty = items.is_empty();
        let enumerator: IEnumOPCItemAttributes =
            ItemAttributesEnum::create(items, ObjectGuard::new(&self.ctx.lifetime));
        // SAFETY: checked non-null above.
        unsafe { ppunk.write(Some(enumerator.into())) };
        if empty {
            S_FALSE
        } else {
            S_OK
        }
    }
}

// ---------------------------------------------------------------------------------------
// IEnumOPCItemAttributes
// ---------------------------------------------------------------------------------------

/// A snapshot of a group's item attributes, taken by CreateEnumerator.
#[implement(IEnumOPCItemAttributes)]
pub struct ItemAttributesEnum {
    cursor: Cursor<ItemAttributes>,
    _guard: ObjectGuard,
}

impl ItemAttributesEnum {
    /// `guard`: the group's context counts the enumerator as a live object.
    pub fn create(items: Vec<ItemAttributes>, guard: ObjectGuard) -> IEnumOPCItemAttributes {
        ItemAttributesEnum {
            cursor: Cursor::new(items),
            _guard: guard,
        }
        .into()
    }
}

/// vEUInfo: OPC_ANALOG a SAFEARRAY of two R8 [low, high], OPC_ENUMERATED a SAFEARRAY of
/// BSTR texts, OPC_NOENUM VT_EMPTY.
fn eu_info(eu: &EuInfo) -> windows::core::Result<(OPCEUTYPE, VARIANT)> {
    Ok(match eu {
        EuInfo::None => (OPC_NOENUM, VARIANT::default()),
        EuInfo::Analog { low, high } => (
            OPC_ANALOG,
            variant::to_variant(&Value::Array(ArrayValue {
                element_type: VarType::R8,
                elements: vec![Value::R8(*low), Value::R8(*high)],
            }))?,
        ),
        EuInfo::Enumerated(texts) => (
            OPC_ENUMERATED,
            variant::to_variant(&Value::Array(ArrayValue {
                element_type: VarType::BSTR,
                elements: texts.iter().map(|t| Value::Bstr(t.clone())).collect(),
            }))?,
        ),
    })
}

fn attributes(a: &ItemAttributes, out: &mut OPCITEMATTRIBUTES) -> windows::core::Result<()> {
    out.szAccessPath = abi::alloc_wstr(&a.access_path)?;
    out.szItemID = abi::alloc_wstr(&a.item_id)?;
    out.bActive = BOOL::from(a.active);
    out.hClient = a.client_handle;
    out.hServer = a.server_handle;
    out.dwAccessRights = a.access_rights;
    out.dwBlobSize = 0;
    out.pBlob = std::ptr::null_mut();
    out.vtRequestedDataType = VARENUM(a.requested_type.0);
    out.vtCanonicalDataType = VARENUM(a.canonical_type.0);
    let (eu_type, eu) = eu_info(&a.eu)?;
    out.dwEUType = eu_type;
    out.vEUInfo = eu;
    Ok(())
}

impl IEnumOPCItemAttributes_Impl for ItemAttributesEnum_Impl {
    unsafe fn Next(
        &self,
        celt: u32,
        ppitemarray: *mut *mut OPCITEMATTRIBUTES,
        pceltfetched: *mut u32,
    ) -> HRESULT {
        // SAFETY: this method's [out] parameters. (*pceltFetched is written below when
        // asked for; a failed Next leaves it as it was, as the enumerators of `enums` do.)
        unsafe { abi::clear_outs((ppitemarray,)) };
        if let Err(hr) = check_next(celt, ppitemarray, pceltfetched) {
            return hr;
        }
        let (pos, end) = self.cursor.peek(celt);
        let got = end - pos;
        if got > 0 {
            // All-or-nothing: until handed out, the array frees its strings and VARIANTs.
            let Ok(mut block) = OwnedArray::<OPCITEMATTRIBUTES>::zeroed(got) else {
                return E_OUTOFMEMORY;
            };
            for (src, dst) in self.cursor.items()[pos..end]
                .iter()
                .zip(block.as_mut_slice().iter_mut())
            {
                if let Err(e) = attributes(src, dst) {
                    return e.code();
                }
            }
            // SAFETY: checked non-null by check_next; every allocation has succeeded.
            unsafe { ppitemarray.write(block.into_raw()) };
        }
        self.cursor.commit(end);
        if !pceltfetched.is_null() {
            // SAFETY: checked non-null.
            unsafe { pceltfetched.write(got as u32) };
        }
        if got == celt as usize {
            S_OK
        } else {
            S_FALSE
        }
    }

    unsafe fn Skip(&self, celt: u32) -> HRESULT {
        self.cursor.skip(celt)
    }

    unsafe fn Reset(&self) -> windows::core::Result<()> {
        self.cursor.reset();
        Ok(())
    }

    unsafe fn Clone(
        &self,
        ppenumitemattributes: *mut Option<IEnumOPCItemAttributes>,
    ) -> windows::core::Result<()> {
        // SAFETY: this method's [out] interface pointer.
        unsafe { abi::clear_outs((ppenumitemattributes,)) };
        if ppenumitemattributes.is_null() {
            return Err(E_INVALIDARG.into());
        }
        let clone: IEnumOPCItemAttributes = ItemAttributesEnum {
            cursor: self.cursor.fork(),
            _guard: self._guard.clone(),
        }
        .into();
        // SAFETY: checked non-null; an [out] interface pointer.
        unsafe { ppenumitemattributes.write(Some(clone)) };
        Ok(())
    }
}

// ---------------------------------------------------------------------------------------
// IOPCItemDeadbandMgt
// ---------------------------------------------------------------------------------------

impl IOPCItemDeadbandMgt_Impl for Group_Impl {
    unsafe fn SetItemDeadband(
        &self,
        dwcount: u32,
        phserver: *const OPCHANDLE,
        ppercentdeadband: *const f32,
        pperrors: *mut *mut HRESULT,
    ) -> HRESULT {
        let errors = check!(OutArray::new(pperrors));
        let handles = check!(in_array(phserver, dwcount));
        let deadbands = check!(in_array(ppercentdeadband, dwcount));
        let pairs: Vec<(u32, f32)> = handles
            .iter()
            .copied()
            .zip(deadbands.iter().copied())
            .collect();
        self.per_item(handles.len(), errors, |e, _, g| {
            e.set_item_deadband(g, &pairs)
        })
    }

    unsafe fn GetItemDeadband(
        &self,
        dwcount: u32,
        phserver: *const OPCHANDLE,
        pppercentdeadband: *mut *mut f32,
        pperrors: *mut *mut HRESULT,
    ) -> HRESULT {
        // SAFETY: this method's [out] parameters.
        unsafe { abi::clear_outs((pppercentdeadband, pperrors)) };
        let values = check!(OutArray::new(pppercentdeadband));
        let errors = check!(OutArray::new(pperrors));
        let handles = check!(in_array(phserver, dwcount));
        self.per_item_values(
            handles.len(),
            values,
            errors,
            |e, _, g| e.get_item_deadband(g, handles),
            plain,
        )
    }

    unsafe fn ClearItemDeadband(
        &self,
        dwcount: u32,
        phserver: *const OPCHANDLE,
        pperrors: *mut *mut HRESULT,
    ) -> HRESULT {
        let errors = check!(OutArray::new(pperrors));
        let handles = check!(in_array(phserver, dwcount));
        self.per_item(handles.len(), errors, |e, _, g| {
            e.clear_item_deadband(g, handles)
        })
    }
}

// ---------------------------------------------------------------------------------------
// IOPCItemSamplingMgt
// ---------------------------------------------------------------------------------------

impl IOPCItemSamplingMgt_Impl for Group_Impl {
    /// Per item: the revised rate, and OPC_S_UNSUPPORTEDRATE (a success code: not counted
    /// for S_FALSE) when it differs from the requested one.
    unsafe fn SetItemSamplingRate(
        &self,
        dwcount: u32,
        phserver: *const OPCHANDLE,
        pdwrequestedsamplingrate: *const u32,
        ppdwrevisedsamplingrate: *mut *mut u32,
        pperrors: *mut *mut HRESULT,
    ) -> HRESULT {
        // SAFETY: this method's [out] parameters.
        unsafe { abi::clear_outs((ppdwrevisedsamplingrate, pperrors)) };
        let values = check!(OutArray::new(ppdwrevisedsamplingrate));
        let errors = check!(OutArray::new(pperrors));
        let handles = check!(in_array(phserver, dwcount));
        let rates = check!(in_array(pdwrequestedsamplingrate, dwcount));
        let pairs: Vec<(u32, u32)> = handles.iter().copied().zip(rates.iter().copied()).collect();
        self.per_item_values(
            handles.len(),
            values,
            errors,
            |e, _, g| e.set_item_sampling_rate(g, &pairs),
            |r| match r {
                Ok(rev) => (rev.value, rev.code().map_or(S_OK, error::hresult)),
                Err(e) => (0, error::hresult(e)),
            },
        )
    }

    unsafe fn GetItemSamplingRate(
        &self,
        dwcount: u32,
        phserver: *const OPCHANDLE,
        ppdwsamplingrate: *mut *mut u32,
        pperrors: *mut *mut HRESULT,
    ) -> HRESULT {
        // SAFETY: this method's [out] parameters.
        unsafe { abi::clear_outs((ppdwsamplingrate, pperrors)) };
        let values = check!(OutArray::new(ppdwsamplingrate));
        let errors = check!(OutArray::new(pperrors));
        let handles = check!(in_array(phserver, dwcount));
        self.per_item_values(
            handles.len(),
            values,
            errors,
            |e, _, g| e.get_item_sampling_rate(g, handles),
            plain,
        )
    }

    unsafe fn ClearItemSamplingRate(
        &self,
        dwcount: u32,
        phserver: *const OPCHANDLE,
        pperrors: *mut *mut HRESULT,
    ) -> HRESULT {
        let errors = check!(OutArray::new(pperrors));
        let handles = check!(in_array(phserver, dwcount));
        self.per_item(handles.len(), errors, |e, _, g| {
            e.clear_item_sampling_rate(g, handles)
        })
    }

    /// Item buffering (`ctopc_core::model::buffer`): the buffered samples reach the client
    /// through the group's ordinary OnDataChange, several per item.
    unsafe fn SetItemBufferEnable(
        &self,
        dwcount: u32,
        phserver: *const OPCHANDLE,
        pbenable: *const BOOL,
        pperrors: *mut *mut HRESULT,
    ) -> HRESULT {
        let errors = check!(OutArray::new(pperrors));
        let handles = check!(in_array(phserver, dwcount));
        let enable = check!(in_array(pbenable, dwcount));
        let pairs: Vec<(u32, bool)> = handles
            .iter()
            .copied()
            .zip(enable.iter().map(|b| b.as_bool()))
            .collect();
        self.per_item(handles.len(), errors, |e, _, g| {
            e.set_item_buffer_enable(g, &pairs)
        })
    }

    unsafe fn GetItemBufferEnable(
        &self,
        dwcount: u32,
        phserver: *const OPCHANDLE,
        ppbenable: *mut *mut BOOL,
        pperrors: *mut *mut HRESULT,
    ) -> HRESULT {
        // SAFETY: this method's [out] parameters.
        unsafe { abi::clear_outs((ppbenable, pperrors)) };
        let values = check!(OutArray::new(ppbenable));
        let errors = check!(OutArray::new(pperrors));
        let handles = check!(in_array(phserver, dwcount));
        self.per_item_values(
            handles.len(),
            values,
            errors,
            |e, _, g| e.get_item_buffer_enable(g, handles),
            |r| match r {
                Ok(b) => (BOOL::from(b), S_OK),
                Err(e) => (BOOL(0), error::hresult(e)),
            },
        )
    }
}
