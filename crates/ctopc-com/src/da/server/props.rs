//! Item properties: IOPCItemProperties (DA 2.05a) and the property part of IOPCBrowse
//! (DA 3.0 GetProperties, Browse with properties), the COM side: argument checks, one
//! core call per method, the one engine read for the live values (2-4) and the
//! marshalling. Which properties an item has, their values and item IDs are the core's
//! (`ctopc_core::properties::item`, tested natively), with the asix item IDs of
//! properties from the namespace (`Namespace::property_item_id`).
//!
//! Values of 2-4 come from one IOPCItemIO-style read of the engine ([`OpcServer::read_values`]):
//! the cache when it was refreshed within `VALUE_MAX_AGE_FACTOR` times the server scan
//! rate (a subscribed item), otherwise a device read. "Server scan rate" is the engine's
//! minimum update rate (the fastest rate the server obtains data at), in milliseconds.

use super::{OpcServer, OpcServer_Impl};
use crate::com::abi::TaskMem;
use crate::com::abi::{
    self, clear_outs, in_slice, in_string, nonnull, opt_wstr, put, s_false_if_any, OwnedArray,
    OwnedWstr,
};
use crate::com::interfaces::*;
use crate::com::variant;
use ctopc_core::lang::Lang;
use ctopc_core::limits;
use ctopc_core::model::ItemState;
use ctopc_core::properties::{fill_live, lookup_item_ids, needs_read, PropertyContext};
pub use ctopc_core::properties::{static_properties, Prop, VALUE_MAX_AGE_FACTOR};
use ctopc_core::{OpcError, OpcResult};
use windows::core::{HRESULT, PCWSTR, PWSTR};
use windows::Win32::Foundation::{S_FALSE, S_OK};
use windows::Win32::System::Variant::{VARENUM, VARIANT};

impl OpcServer {
    /// The session's language (descriptions, texts).
    pub(super) fn lang(&self) -> Lang {
        self.lang_for(self.session().lcid)
            .unwrap_or(self.ctx.default_lang)
    }

    /// The engine's minimum update rate (the "Server Scan Rate" property).
    pub(super) fn scan_rate_ms(&self) -> u32 {
        self.ctx.runtime.lock().engine.config().min_update_rate_ms
    }

    /// Reads value, quality and timestamp of `item_ids` for their properties: one engine
    /// read for all of them (see the module documentation for the MaxAge used).
    pub(super) fn read_values(&self, item_ids: &[&str]) -> Vec<Result<ItemState, OpcError>> {
        if item_ids.is_empty() {
            return Vec::new();
        }
        let max_age = self.scan_rate_ms().saturating_mul(VALUE_MAX_AGE_FACTOR);
        let items: Vec<(&str, u32)> = item_ids.iter().map(|id| (*id, max_age)).collect();
        self.item_io_read(&items)
    }
}

/// The item-level code of GetProperties / Browse: the item's error, S_FALSE when a
/// property failed, else S_OK.
pub fn item_code(r: &OpcResult<Vec<Prop>>) -> HRESULT {
    match r {
        Err(e) => crate::com::error::hresult(*e),
        Ok(props) if props.iter().any(|p| p.error.is_some()) => S_FALSE,
        Ok(_) => S_OK,
    }
}

/// The OPCITEMPROPERTIES of one item (owning its array and strings: store it in an
/// [`OwnedArray`] at once).
pub fn item_properties(r: &OpcResult<Vec<Prop>>) -> windows::core::Result<OPCITEMPROPERTIES> {
    let hr = item_code(r);
    let props = match r {
        Ok(p) => p.as_slice(),
        Err(_) => &[],
    };
    let mut arr = OwnedArray::<OPCITEMPROPERTY>::zeroed(props.len())?;
    for (slot, prop) in arr.as_mut_slice().iter_mut().zip(props) {
        slot.dwPropertyID = prop.id;
        slot.hrErrorID = prop.error.map_or(S_OK, crate::com::error::hresult);
        if prop.error.is_none() {
            slot.vtDataType = VARENUM(prop.var_type.0);
            slot.szDescription = opt_wstr(Some(prop.description))?;
            slot.szItemID = opt_wstr(prop.item_id.as_deref())?;
            slot.vValue = variant::to_variant(&prop.value)?;
        }
    }
    Ok(OPCITEMPROPERTIES {
        hrErrorID: hr,
        dwNumProperties: props.len() as u32,
        pItemProperties: arr.into_raw(),
        dwReserved: 0,
    })
}

impl OpcServer {
    /// The context for property lookups in this session.
    pub(super) fn props_ctx(&self) -> PropertyContext<'_> {
        PropertyContext {
            ns: &*self.ctx.namespace,
            lang: self.lang(),
            scan_rate_ms: self.scan_rate_ms(),
        }
    }

    /// Fills the live properties (2-4) of every item that asked for them, with one read.
    pub(super) fn fill_live_values(&self, items: &mut [(&str, &mut Vec<Prop>)]) {
        let wanted: Vec<usize> = (0..items.len())
            .filter(|&i| needs_read(items[i].1))
            .collect();
        let ids: Vec<&str> = wanted.iter().map(|&i| items[i].0).collect();
        let reads = self.read_values(&ids);
        for (&i, read) in wanted.iter().zip(&reads) {
            fill_live(items[i].1, read);
        }
    }
}

impl IOPCItemProperties_Impl for OpcServer_Impl {
    unsafe fn QueryAvailableProperties(
        &self,
        pitem_id: PCWSTR,
        pcount: *mut u32,
        ppids: *mut *mut u32,
        ppdescriptions: *mut *mut PWSTR,
        pptypes: *mut *mut VARTYPE,
    ) -> windows::core::Result<()> {
        clear_outs((pcount, ppids, ppdescriptions, pptypes));
        nonnull(pcount)?;
        nonnull(ppids)?;
        nonnull(ppdescriptions)?;
        nonnull(pptypes)?;
        let item_id = in_string(pitem_id, limits::ITEM_ID)?;
        let cx = self.props_ctx();
        let props =
            static_properties(&cx, &item_id, None, false).map_err(crate::com::error::to_com)?;
        let n = props.len();
        let mut ids = TaskMem::<u32>::zeroed(n)?;
        let mut types = TaskMem::<VARTYPE>::zeroed(n)?;
        let mut descriptions = OwnedArray::<PWSTR>::zeroed(n)?;
        for (i, prop) in props.iter().enumerate() {
            ids.as_mut_slice()[i] = prop.id;
            types.as_mut_slice()[i] = VARENUM(prop.var_type.0);
            descriptions.as_mut_slice()[i] = OwnedWstr::new(prop.description)?.into_raw();
        }
        // SAFETY: all four checked non-null; every allocation has succeeded.
        unsafe {
            put(pcount, n as u32);
            put(ppids, ids.into_raw());
            put(ppdescriptions, descriptions.into_raw());
            put(pptypes, types.into_raw());
        }
        Ok(())
    }

    unsafe fn GetItemProperties(
        &self,
        pitem_id: PCWSTR,
        count: u32,
        pids: *const u32,
        ppdata: *mut *mut VARIANT,
        pperrors: *mut *mut HRESULT,
    ) -> HRESULT {
        clear_outs((ppdata, pperrors));
        abi::hresult((|| {
            nonnull(ppdata)?;
            nonnull(pperrors)?;
            if count == 0 {
                return Err(abi::invalid_arg());
            }
            let ids = in_slice(pids, count)?;
            let item_id = in_string(pitem_id, limits::ITEM_ID)?;
            let cx = self.props_ctx();
            let mut props = static_properties(&cx, &item_id, Some(ids), true)
                .map_err(crate::com::error::to_com)?;
            self.fill_live_values(&mut [(item_id.as_str(), &mut props)]);
            let mut data = OwnedArray::<VARIANT>::zeroed(props.len())?;
            let mut errors = TaskMem::<HRESULT>::zeroed(props.len())?;
            for (i, prop) in props.iter().enumerate() {
                errors.as_mut_slice()[i] = prop.error.map_or(S_OK, crate::com::error::hresult);
                if prop.error.is_none() {
                    data.as_mut_slice()[i] = variant::to_variant(&prop.value)?;
                }
            }
            let hr = s_false_if_any(errors.as_mut_slice());
            // SAFETY: both checked non-null; every allocation has succeeded.
            unsafe {
                put(ppdata, data.into_raw());
                put(pperrors, errors.into_raw());
            }
            Ok(hr)
        })())
    }

    unsafe fn LookupItemIDs(
        &self,
        pitem_id: PCWSTR,
        count: u32,
        pids: *const u32,
        ppnew_ids: *mut *mut PWSTR,
        pperrors: *mut *mut HRESULT,
    ) -> HRESULT {
        clear_outs((ppnew_ids, pperrors));
        abi::hresult((|| {
            nonnull(ppnew_ids)?;
            nonnull(pperrors)?;
            if count == 0 {
                return Err(abi::invalid_arg());
            }
            let ids = in_slice(pids, count)?;
            let item_id = in_string(pitem_id, limits::ITEM_ID)?;
            let cx = self.props_ctx();
            let found = lookup_item_ids(&cx, &item_id, ids).map_err(crate::com::error::to_com)?;
            let mut new_ids = OwnedArray::<PWSTR>::zeroed(found.len())?;
            let mut errors = TaskMem::<HRESULT>::zeroed(found.len())?;
            for (i, r) in found.iter().enumerate() {
                match r {
                    Ok(new_id) => {
                        new_ids.as_mut_slice()[i] = OwnedWstr::new(new_id)?.into_raw();
                        errors.as_mut_slice()[i] = S_OK;
                    }
                    Err(e) => errors.as_mut_slice()[i] = crate::com::error::hresult(*e),
                }
            }
            let hr = s_false_if_any(errors.as_mut_slice());
            // SAFETY: both checked non-null; every allocation has succeeded.
            unsafe {
                put(ppnew_ids, new_ids.into_raw());
                put(pperrors, errors.into_raw());
            }
            Ok(hr)
        })())
    }
}
