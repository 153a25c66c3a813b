//! Browsing: IOPCBrowseServerAddressSpace (DA 2.05a, a per-session cursor) and IOPCBrowse
//! (DA 3.0, stateless with continuation points). The rules (which code for which case) are
//! the core's: see `ctopc_core::browse`. Here: argument checks and the COM shapes.
//!
//! - BrowseOPCItemIDs: an empty list is S_FALSE with an empty enumerator (OPC Foundation
//!   sample: `(uCount > 0) ? S_OK : S_FALSE`); an access-rights filter with bits other
//!   than OPC_READABLE | OPC_WRITEABLE is E_INVALIDARG (sample); the access-rights and
//!   data-type filters apply as DA 2.05a defines them (the asix original ignored them:
//!   `ctopc_core::browse::BrowseCursor::browse_opc_item_ids`, items resolved through the
//!   context's namespace), and so to the strings of the returned enumerator.
//! - Every browse path includes the `_Diagnostics` branch beside the real address space
//!   (`ctopc_core::diagnostics::browse`: the session's cursor and `browse`), over the
//!   branch's tree of the current snapshot (`Runtime::diagnostics`).
//! - BrowseAccessPaths: E_NOTIMPL, as the original (asix channels are not browsable).
//! - Browse: the `[in, out]` continuation point is replaced only when the call succeeds
//!   (the client's string is freed then); when the browse is complete the server writes an
//!   empty string (the sample does the same, and clients that `wcslen` it do not crash).
//!   Browse returns S_FALSE when some element's properties failed (sample).

use super::props::{self, Prop};
use super::OpcServer_Impl;
use crate::com::abi::{
    self, clear, clear_outs, in_slice, in_string, nonnull, put, OwnedArray, OwnedWstr,
};
use crate::com::enums::StringEnum;
use crate::com::interfaces::*;
use ctopc_core::browse::{
    BrowseDirection, BrowseElement, BrowseFilter, BrowseRequest, BrowseResult, BrowseType,
    PropertySelection,
};
use ctopc_core::diagnostics::browse::browse;
use ctopc_core::limits;
use ctopc_core::metrics::Method;
use ctopc_core::{OpcError, OpcResult};
use std::sync::Arc;
use windows::core::{BOOL, HRESULT, PCWSTR, PWSTR};
use windows::Win32::Foundation::{E_NOTIMPL, S_FALSE, S_OK};
use windows::Win32::System::Com::IEnumString;

/// An enumeration argument: values outside the IDL's are E_INVALIDARG.
fn enum_arg<T: TryFrom<u32, Error = OpcError>>(v: i32) -> windows::core::Result<T> {
    u32::try_from(v)
        .map_err(|_| abi::invalid_arg())
        .and_then(|v| T::try_from(v).map_err(crate::com::error::to_com))
}

impl IOPCBrowseServerAddressSpace_Impl for OpcServer_Impl {
    unsafe fn QueryOrganization(&self, pns: *mut OPCNAMESPACETYPE) -> windows::core::Result<()> {
        nonnull(pns)?;
        let ns = self.cursor().query_organization();
        // SAFETY: checked non-null.
        unsafe { put(pns, OPCNAMESPACETYPE(u32::from(ns) as i32)) };
        Ok(())
    }

    unsafe fn ChangeBrowsePosition(
        &self,
        direction: OPCBROWSEDIRECTION,
        pname: PCWSTR,
    ) -> windows::core::Result<()> {
        let direction: BrowseDirection = enum_arg(direction.0)?;
        let name = in_string(pname, limits::ITEM_ID.with_error(OpcError::InvalidArg))?;
        let diag = self.ctx.runtime.diagnostics.space();
        self.cursor()
            .change_browse_position(direction, &name, &diag)
            .map_err(crate::com::error::to_com)
    }

    unsafe fn BrowseOPCItemIDs(
        &self,
        browse_type: OPCBROWSETYPE,
        pfilter: PCWSTR,
        data_type_filter: VARTYPE,
        access_rights_filter: u32,
        ppenum: *mut Option<IEnumString>,
    ) -> HRESULT {
        let _t = self.ctx.timed(Method::BrowseOpcItemIds);
        clear(ppenum, None);
        abi::hresult((|| {
            nonnull(ppenum)?;
            let browse_type: BrowseType = enum_arg(browse_type.0)?;
            if access_rights_filter & !(OPC_READABLE | OPC_WRITEABLE) != 0 {
                return Err(abi::invalid_arg());
            }
            let filter = in_string(pfilter, limits::FILTER)?;
            let diag = self.ctx.runtime.diagnostics.space();
            let names = self
                .cursor()
                .browse_opc_item_id_list(
                    browse_type,
                    &filter,
                    data_type_filter.0,
                    access_rights_filter,
                    &*self.ctx.namespace,
                    &diag,
                )
                .map_err(crate::com::error::to_com)?;
            let hr = if names.is_empty() { S_FALSE } else { S_OK };
            // SAFETY: checked non-null.
            unsafe { put(ppenum, Some(StringEnum::of(Arc::new(names)))) };
            Ok(hr)
        })())
    }

    unsafe fn GetItemID(
        &self,
        pdata_id: PCWSTR,
        pitem_id: *mut PWSTR,
    ) -> windows::core::Result<()> {
        clear(pitem_id, PWSTR::null());
        nonnull(pitem_id)?;
        let data_id = in_string(pdata_id, limits::ITEM_ID.with_error(OpcError::InvalidArg))?;
        let diag = self.ctx.runtime.diagnostics.space();
        let id = self
            .cursor()
            .get_item_id(&data_id, &diag)
            .map_err(crate::com::error::to_com)?;
        let id = OwnedWstr::new(&id)?;
        // SAFETY: checked non-null; the only allocation has succeeded.
        unsafe { put(pitem_id, id.into_raw()) };
        Ok(())
    }

    unsafe fn BrowseAccessPaths(
        &self,
        pitem_id: PCWSTR,
        ppenum: *mut Option<IEnumString>,
    ) -> HRESULT {
        clear(ppenum, None);
        abi::hresult((|| {
            nonnull(ppenum)?;
            let item_id = in_string(pitem_id, limits::ITEM_ID)?;
            self.cursor()
                .browse_access_paths(&item_id)
                .map_err(crate::com::error::to_com)?;
            Err(E_NOTIMPL.into())
        })())
    }
}

/// One browse element's properties (items only, when properties were asked for).
type ElementProps = OpcResult<Vec<Prop>>;

impl IOPCBrowse_Impl for OpcServer_Impl {
    unsafe fn GetProperties(
        &self,
        count: u32,
        pitem_ids: *const PCWSTR,
        return_values: BOOL,
        property_count: u32,
        pproperty_ids: *const u32,
        ppitem_properties: *mut *mut OPCITEMPROPERTIES,
    ) -> HRESULT {
        clear(ppitem_properties, std::ptr::null_mut());
        abi::hresult((|| {
            nonnull(ppitem_properties)?;
            if count == 0 {
                return Err(abi::invalid_arg());
            }
            let item_ids: Vec<OpcResult<String>> = in_slice(pitem_ids, count)?
                .iter()
                .map(|p| abi::item_id_at(*p))
                .collect();
            let ids = in_slice(pproperty_ids, property_count)?;
            let ids = (!ids.is_empty()).then_some(ids);
            let with_values = return_values.as_bool();
            let cx = self.props_ctx();
            let mut results: Vec<OpcResult<Vec<Prop>>> = item_ids
                .iter()
                .map(|id| {
                    id.clone()
                        .and_then(|id| props::static_properties(&cx, &id, ids, with_values))
                })
                .collect();
            if with_values {
                let mut wanted: Vec<(&str, &mut Vec<Prop>)> = item_ids
                    .iter()
                    .zip(results.iter_mut())
                    .filter_map(|(id, r)| Some((id.as_deref().ok()?, r.as_mut().ok()?)))
                    .collect();
                self.fill_live_values(&mut wanted);
            }
            let mut arr = OwnedArray::<OPCITEMPROPERTIES>::zeroed(results.len())?;
            let mut failed = false;
            for (slot, r) in arr.as_mut_slice().iter_mut().zip(&results) {
                *slot = props::item_properties(r)?;
                failed |= slot.hrErrorID != S_OK;
            }
            // SAFETY: checked non-null; every allocation has succeeded.
            unsafe { put(ppitem_properties, arr.into_raw()) };
            Ok(if failed { S_FALSE } else { S_OK })
        })())
    }

    unsafe fn Browse(
        &self,
        pitem_id: PCWSTR,
        pcontinuation_point: *mut PWSTR,
        max_elements: u32,
        filter: OPCBROWSEFILTER,
        pname_filter: PCWSTR,
        pvendor_filter: PCWSTR,
        return_all_properties: BOOL,
        return_values: BOOL,
        property_count: u32,
        pproperty_ids: *const u32,
        pmore: *mut BOOL,
        pcount: *mut u32,
        ppelements: *mut *mut OPCBROWSEELEMENT,
    ) -> HRESULT {
        let _t = self.ctx.timed(Method::Browse);
        clear_outs((pmore, pcount, ppelements));
        abi::hresult((|| {
            nonnull(pcontinuation_point)?;
            nonnull(pmore)?;
            nonnull(pcount)?;
            nonnull(ppelements)?;
            let filter: BrowseFilter = enum_arg(filter.0)?;
            let item_id = in_string(
                pitem_id,
                limits::ITEM_ID.with_error(OpcError::UnknownItemId),
            )?;
            let name_filter = in_string(pname_filter, limits::FILTER)?;
            let vendor_filter = in_string(pvendor_filter, limits::FILTER)?;
            // SAFETY: checked non-null: the [in, out] continuation point is a CoTaskMem
            // string or NULL, owned by this call until replaced below.
            let incoming = unsafe { *pcontinuation_point };
            let cp = if incoming.is_null() {
                String::new()
            } else {
                // SAFETY: a non-null [in, out, string] is a NUL-terminated UTF-16 string.
                abi::limited_wide(unsafe { incoming.as_wide() }, limits::CONTINUATION_POINT)
                    .map_err(crate::com::error::to_com)?
            };
            let ids = in_slice(pproperty_ids, property_count)?;
            let selection = PropertySelection::from_args(return_all_properties.as_bool(), ids);
            let req = BrowseRequest {
                item_id: &item_id,
                continuation_point: &cp,
                max_elements,
                filter,
                element_name_filter: &name_filter,
                vendor_filter: &vendor_filter,
            };
            let space = &self.ctx.address_space;
            let diag = self.ctx.runtime.diagnostics.space();
            let with_values = return_values.as_bool();
            let cx = self.props_ctx();
            let mut result = match selection {
                None => browse(space, &diag, &req, |s, q| s.browse(q)).map(|r| BrowseResult::<
                    ElementProps,
                > {
                    elements: r
                        .elements
                        .into_iter()
                        .map(|e| BrowseElement {
                            name: e.name,
                            item_id: e.item_id,
                            has_children: e.has_children,
                            is_item: e.is_item,
                            properties: None,
                        })
                        .collect(),
                    continuation_point: r.continuation_point,
                    more_elements: r.more_elements,
                }),
                Some(sel) => {
                    let ids = match sel {
                        PropertySelection::All => None,
                        PropertySelection::Ids(ids) => Some(ids),
                    };
                    browse(space, &diag, &req, |s, q| {
                        s.browse_with_properties(q, |id| {
                            props::static_properties(&cx, id, ids, with_values)
                        })
                    })
                }
            }
            .map_err(crate::com::error::to_com)?;
            if with_values {
                let mut wanted: Vec<(&str, &mut Vec<Prop>)> = result
                    .elements
                    .iter_mut()
                    .filter_map(|e| match &mut e.properties {
                        Some(Ok(p)) => Some((e.item_id.as_str(), p)),
                        _ => None,
                    })
                    .collect();
                self.fill_live_values(&mut wanted);
            }
            let n = result.elements.len();
            let mut elements = OwnedArray::<OPCBROWSEELEMENT>::zeroed(n)?;
            let mut failed = false;
            for (slot, e) in elements.as_mut_slice().iter_mut().zip(&result.elements) {
                slot.szName = OwnedWstr::new(&e.name)?.into_raw();
                slot.szItemID = OwnedWstr::new(&e.item_id)?.into_raw();
                slot.dwFlagValue = e.flags();
                if let Some(p) = &e.properties {
                    slot.ItemProperties = props::item_properties(p)?;
                    failed |= slot.ItemProperties.hrErrorID != S_OK;
                }
            }
            let next = OwnedWstr::new(&result.continuation_point)?;
            // SAFETY: all checked non-null; every allocation has succeeded. The incoming
            // continuation point is freed exactly once and replaced.
            unsafe {
                abi::free_wstr(incoming);
                put(pcontinuation_point, next.into_raw());
                put(pmore, BOOL::from(result.more_elements));
                put(pcount, n as u32);
                put(ppelements, elements.into_raw());
            }
            Ok(if failed { S_FALSE } else { S_OK })
        })())
    }
}
