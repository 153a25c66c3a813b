//! Safe wrappers of the server object's interfaces beyond IOPCServer's status and
//! IOPCCommon: group management (AddGroup, GetGroupByName, RemoveGroup,
//! CreateGroupEnumerator), IOPCBrowseServerAddressSpace, IOPCItemProperties, IOPCBrowse,
//! IOPCItemIO and the IOPCShutdown connection point. Every CoTaskMem block the server
//! hands out is copied and freed here.

use super::{take_array, take_variants, take_wstr, timestamp, ReadItem, Server};
use ctopc_com::interfaces::*;
use ctopc_core::model::ItemVqt;
use ctopc_core::Value;
use std::ffi::c_void;
use windows::core::{IUnknown, Interface, BOOL, GUID, HRESULT, HSTRING, PCWSTR, PWSTR};
use windows::Win32::Foundation::FILETIME;
use windows::Win32::System::Com::{
    CoTaskMemFree, IConnectionPointContainer, IEnumString, IEnumUnknown,
};
use windows::Win32::System::Variant::VARIANT;

/// The result of AddGroup, owned.
pub struct AddedGroup {
    /// S_OK or OPC_S_UNSUPPORTEDRATE.
    pub code: HRESULT,
    pub server_handle: u32,
    pub revised_rate: u32,
    /// The group object, as the interface asked for (IUnknown unless `add_group_as`).
    pub object: IUnknown,
}

/// AddGroup's arguments.
#[derive(Debug, Clone, PartialEq)]
pub struct GroupSpec {
    pub name: String,
    pub active: bool,
    pub rate_ms: u32,
    pub client_handle: u32,
    /// `None` passes NULL (the server's bias).
    pub time_bias: Option<i32>,
    /// `None` passes NULL (0 %).
    pub deadband: Option<f32>,
    pub lcid: u32,
}

impl GroupSpec {
    /// An active group with a 1000 ms rate, NULL bias and deadband, English.
    pub fn new(name: &str) -> GroupSpec {
        GroupSpec {
            name: name.into(),
            active: true,
            rate_ms: 1000,
            client_handle: 1,
            time_bias: None,
            deadband: None,
            lcid: 0x0409,
        }
    }
}

/// One OPCITEMPROPERTY, owned.
#[derive(Debug, Clone, PartialEq)]
pub struct Property {
    pub id: u32,
    pub vt: u16,
    pub description: Option<String>,
    pub item_id: Option<String>,
    pub value: Value,
    pub error: HRESULT,
}

/// One OPCITEMPROPERTIES, owned.
#[derive(Debug, Clone, PartialEq)]
pub struct ItemProperties {
    pub error: HRESULT,
    pub properties: Vec<Property>,
}

/// One OPCBROWSEELEMENT, owned.
#[derive(Debug, Clone, PartialEq)]
pub struct BrowseElement {
    pub name: Option<String>,
    pub item_id: Option<String>,
    pub flags: u32,
    pub properties: ItemProperties,
}

/// IOPCBrowse::Browse's arguments.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct BrowseArgs {
    pub item_id: String,
    /// `None` passes a NULL continuation point.
    pub continuation_point: Option<String>,
    pub max_elements: u32,
    /// OPC_BROWSE_FILTER_* (0 is sent as is: invalid).
    pub filter: i32,
    pub name_filter: String,
    pub vendor_filter: String,
    pub all_properties: bool,
    pub property_values: bool,
    pub property_ids: Vec<u32>,
}

impl BrowseArgs {
    /// Every element of `item_id`, no properties.
    pub fn all(item_id: &str) -> BrowseArgs {
        BrowseArgs {
            item_id: item_id.into(),
            filter: OPC_BROWSE_FILTER_ALL.0,
            ..Default::default()
        }
    }
}

/// IOPCBrowse::Browse's results, owned.
#[derive(Debug, Clone, PartialEq)]
pub struct BrowsePage {
    pub code: HRESULT,
    pub continuation_point: Option<String>,
    pub more_elements: bool,
    pub elements: Vec<BrowseElement>,
}

/// One result of LookupItemIDs: the property's item ID (NULL on failure) and its code.
pub type NewItemId = (Option<String>, HRESULT);

/// The HRESULT of a method that may return S_FALSE: failures become `Err`.
fn ok_or_s_false(hr: HRESULT) -> windows::core::Result<HRESULT> {
    if hr.is_err() {
        Err(hr.into())
    } else {
        Ok(hr)
    }
}

/// NUL-terminated UTF-16 copies of strings, alive while the value lives.
struct WideStrings(Vec<HSTRING>);

impl WideStrings {
    fn new(items: &[&str]) -> WideStrings {
        WideStrings(items.iter().map(|s| HSTRING::from(*s)).collect())
    }
    fn pointers(&self) -> Vec<PCWSTR> {
        self.0.iter().map(|h| PCWSTR(h.as_ptr())).collect()
    }
}

fn take_value(v: &mut VARIANT) -> Value {
    let value = ctopc_com::variant::from_variant(v).unwrap_or(Value::Empty);
    ctopc_com::variant::clear(v);
    value
}

/// Takes an OPCITEMPROPERTIES (its array and strings; not the struct itself).
fn take_item_properties(p: &mut OPCITEMPROPERTIES) -> ItemProperties {
    let mut out = ItemProperties {
        error: p.hrErrorID,
        properties: Vec::new(),
    };
    if !p.pItemProperties.is_null() {
        // SAFETY: the server allocated `dwNumProperties` initialised elements; each is
        // taken once, then the block is freed once.
        let props = unsafe {
            std::slice::from_raw_parts_mut(p.pItemProperties, p.dwNumProperties as usize)
        };
        for prop in props.iter_mut() {
            out.properties.push(Property {
                id: prop.dwPropertyID,
                vt: prop.vtDataType.0,
                // SAFETY: each element's strings are NULL or CoTaskMem, ours, taken once
                // (see the slice above).
                description: unsafe { take_wstr(prop.szDescription) },
                // SAFETY: as above.
                item_id: unsafe { take_wstr(prop.szItemID) },
                value: take_value(&mut prop.vValue),
                error: prop.hrErrorID,
            });
        }
        // SAFETY: as above.
        unsafe { CoTaskMemFree(Some(p.pItemProperties as *const c_void)) };
    }
    out
}

/// Strings asked for per `IEnumString::Next` by [`enum_strings`]: thousands per round trip,
/// so that a listing of 1,000,000 item IDs takes a few hundred calls, not 60,000.
pub const STRING_BATCH: usize = 4096;

/// Takes the strings of an enumerator to the end.
pub fn enum_strings(e: &IEnumString) -> windows::core::Result<Vec<String>> {
    let mut out = Vec::new();
    enum_strings_each(e, |batch| out.extend(batch))?;
    Ok(out)
}

/// Takes the strings of an enumerator to the end, [`STRING_BATCH`] per `Next`, handing
/// each batch to `each` as it arrives (for listings too long to hold, or to show progress).
pub fn enum_strings_each(
    e: &IEnumString,
    mut each: impl FnMut(Vec<String>),
) -> windows::core::Result<()> {
    let mut batch = vec![PWSTR::null(); STRING_BATCH];
    loop {
        let mut fetched = 0u32;
        // SAFETY: `batch` has room for STRING_BATCH elements (the slice length is the
        // celt passed); `fetched` is a valid out-pointer.
        let hr = unsafe { e.Next(&mut batch, Some(&mut fetched)) };
        let got = (fetched as usize).min(batch.len());
        let strings: Vec<String> = batch[..got]
            .iter()
            // SAFETY: the `got` fetched elements are CoTaskMem strings handed out by Next,
            // ours; each is taken once and its slot cleared below.
            .filter_map(|p| unsafe { take_wstr(*p) })
            .collect();
        batch[..got].fill(PWSTR::null());
        each(strings);
        hr.ok()?;
        if hr != windows::Win32::Foundation::S_OK || got == 0 {
            return Ok(());
        }
    }
}

/// Takes the objects of an enumerator to the end, one `Next(1)` at a time until no object
/// comes back. (Under Wine 8 the IEnumUnknown proxy unmarshals the return value and
/// `pceltFetched` from the wrong buffer position whenever interface pointers were
/// returned: the HRESULT of a call that returned an object is garbage there. Asking for
/// one object at a time and looking at the object itself works on Windows and Wine.)
pub fn enum_unknowns(e: &IEnumUnknown) -> windows::core::Result<Vec<IUnknown>> {
    let mut out = Vec::new();
    loop {
        let mut one: [Option<IUnknown>; 1] = Default::default();
        // SAFETY: `one` has room for the one element asked for; `pceltFetched` may be NULL
        // when one element is asked for.
        let hr = unsafe { e.Next(&mut one, None) };
        match one[0].take() {
            Some(u) => out.push(u),
            None => {
                hr.ok()?;
                return Ok(out);
            }
        }
    }
}

impl Server {
    // ---- groups -------------------------------------------------------------------------

    /// IOPCServer::AddGroup asking for `riid`.
    pub fn add_group_as(&self, spec: &GroupSpec, riid: &GUID) -> windows::core::Result<AddedGroup> {
        let name = HSTRING::from(spec.name.as_str());
        let bias = spec.time_bias;
        let deadband = spec.deadband;
        let mut handle = 0u32;
        let mut revised = 0u32;
        let mut unk: Option<IUnknown> = None;
        // SAFETY: every pointer is valid for the call; optional inputs are NULL or point to
        // locals; the object is returned AddRef'd into `unk`.
        let hr = unsafe {
            self.server.AddGroup(
                PCWSTR(name.as_ptr()),
                BOOL::from(spec.active),
                spec.rate_ms,
                spec.client_handle,
                bias.as_ref().map_or(std::ptr::null(), |b| b as *const i32),
                deadband
                    .as_ref()
                    .map_or(std::ptr::null(), |d| d as *const f32),
                spec.lcid,
                &mut handle,
                &mut revised,
                riid,
                &mut unk,
            )
        };
        let _ = ok_or_s_false(hr)?;
        let object =
            unk.ok_or_else(|| windows::core::Error::from(windows::Win32::Foundation::E_POINTER))?;
        Ok(AddedGroup {
            code: hr,
            server_handle: handle,
            revised_rate: revised,
            object,
        })
    }

    /// IOPCServer::AddGroup asking for IUnknown.
    pub fn add_group(&self, spec: &GroupSpec) -> windows::core::Result<AddedGroup> {
        self.add_group_as(spec, &IUnknown::IID)
    }

    /// IOPCServer::GetGroupByName asking for `riid`.
    pub fn group_by_name_as(&self, name: &str, riid: &GUID) -> windows::core::Result<IUnknown> {
        let name = HSTRING::from(name);
        let mut unk: Option<IUnknown> = None;
        // SAFETY: valid pointers for the call.
        unsafe {
            self.server
                .GetGroupByName(PCWSTR(name.as_ptr()), riid, &mut unk)?
        };
        unk.ok_or_else(|| windows::Win32::Foundation::E_POINTER.into())
    }

    /// IOPCServer::GetGroupByName asking for IUnknown.
    pub fn group_by_name(&self, name: &str) -> windows::core::Result<IUnknown> {
        self.group_by_name_as(name, &IUnknown::IID)
    }

    /// IOPCServer::RemoveGroup: S_OK or OPC_S_INUSE.
    pub fn remove_group(&self, server_handle: u32, force: bool) -> windows::core::Result<HRESULT> {
        // SAFETY: plain values.
        ok_or_s_false(unsafe { self.server.RemoveGroup(server_handle, BOOL::from(force)) })
    }

    /// IOPCServer::CreateGroupEnumerator for `riid`, raw: (S_OK or S_FALSE, the enumerator).
    pub fn group_enumerator(
        &self,
        scope: OPCENUMSCOPE,
        riid: &GUID,
    ) -> windows::core::Result<(HRESULT, IUnknown)> {
        let mut unk: Option<IUnknown> = None;
        // SAFETY: valid pointers for the call.
        let hr =
            ok_or_s_false(unsafe { self.server.CreateGroupEnumerator(scope, riid, &mut unk) })?;
        Ok((
            hr,
            unk.ok_or_else(|| windows::core::Error::from(windows::Win32::Foundation::E_POINTER))?,
        ))
    }

    /// The names of the groups in `scope` (IEnumString), with the call's code.
    pub fn group_names(
        &self,
        scope: OPCENUMSCOPE,
    ) -> windows::core::Result<(HRESULT, Vec<String>)> {
        let (hr, e) = self.group_enumerator(scope, &IEnumString::IID)?;
        Ok((hr, enum_strings(&e.cast()?)?))
    }

    /// The group objects in `scope` (IEnumUnknown), with the call's code.
    pub fn group_objects(
        &self,
        scope: OPCENUMSCOPE,
    ) -> windows::core::Result<(HRESULT, Vec<IUnknown>)> {
        let (hr, e) = self.group_enumerator(scope, &IEnumUnknown::IID)?;
        Ok((hr, enum_unknowns(&e.cast()?)?))
    }

    // ---- IOPCBrowseServerAddressSpace ---------------------------------------------------

    pub fn address_space(&self) -> windows::core::Result<IOPCBrowseServerAddressSpace> {
        self.unknown.cast()
    }

    pub fn query_organization(&self) -> windows::core::Result<OPCNAMESPACETYPE> {
        let mut ns = OPCNAMESPACETYPE(0);
        // SAFETY: valid out-pointer.
        unsafe { self.address_space()?.QueryOrganization(&mut ns)? };
        Ok(ns)
    }

    pub fn change_browse_position(
        &self,
        direction: OPCBROWSEDIRECTION,
        name: &str,
    ) -> windows::core::Result<()> {
        let name = HSTRING::from(name);
        // SAFETY: valid string for the call.
        unsafe {
            self.address_space()?
                .ChangeBrowsePosition(direction, PCWSTR(name.as_ptr()))
        }
    }

    /// BrowseOPCItemIDs: (S_OK or S_FALSE, the strings).
    pub fn browse_item_ids(
        &self,
        browse_type: OPCBROWSETYPE,
        filter: &str,
        vt: u16,
        rights: u32,
    ) -> windows::core::Result<(HRESULT, Vec<String>)> {
        let mut out = Vec::new();
        let hr = self.browse_item_ids_each(browse_type, filter, vt, rights, |b| out.extend(b))?;
        Ok((hr, out))
    }

    /// BrowseOPCItemIDs, the strings handed to `each` a batch ([`STRING_BATCH`]) at a time
    /// as they arrive: S_OK or S_FALSE.
    pub fn browse_item_ids_each(
        &self,
        browse_type: OPCBROWSETYPE,
        filter: &str,
        vt: u16,
        rights: u32,
        each: impl FnMut(Vec<String>),
    ) -> windows::core::Result<HRESULT> {
        let filter = HSTRING::from(filter);
        let mut e: Option<IEnumString> = None;
        // SAFETY: valid pointers for the call.
        let hr = ok_or_s_false(unsafe {
            self.address_space()?.BrowseOPCItemIDs(
                browse_type,
                PCWSTR(filter.as_ptr()),
                windows::Win32::System::Variant::VARENUM(vt),
                rights,
                &mut e,
            )
        })?;
        let e =
            e.ok_or_else(|| windows::core::Error::from(windows::Win32::Foundation::E_POINTER))?;
        enum_strings_each(&e, each)?;
        Ok(hr)
    }

    pub fn get_item_id(&self, item_data_id: &str) -> windows::core::Result<Option<String>> {
        let s = HSTRING::from(item_data_id);
        let mut p = PWSTR::null();
        // SAFETY: valid pointers for the call.
        unsafe {
            self.address_space()?
                .GetItemID(PCWSTR(s.as_ptr()), &mut p)?
        };
        // SAFETY: NULL or the CoTaskMem string the call handed out, ours.
        Ok(unsafe { take_wstr(p) })
    }

    /// BrowseAccessPaths: the call's code (the enumerator is dropped).
    pub fn browse_access_paths(&self, item_id: &str) -> windows::core::Result<HRESULT> {
        let s = HSTRING::from(item_id);
        let mut e: Option<IEnumString> = None;
        // SAFETY: valid pointers for the call.
        ok_or_s_false(unsafe {
            self.address_space()?
                .BrowseAccessPaths(PCWSTR(s.as_ptr()), &mut e)
        })
    }

    // ---- IOPCItemProperties -------------------------------------------------------------

    pub fn item_properties_itf(&self) -> windows::core::Result<IOPCItemProperties> {
        self.unknown.cast()
    }

    /// QueryAvailableProperties: (ID, description, VARTYPE) per property.
    pub fn query_available_properties(
        &self,
        item_id: &str,
    ) -> windows::core::Result<Vec<(u32, Option<String>, u16)>> {
        let s = HSTRING::from(item_id);
        let mut n = 0u32;
        let (mut ids, mut descs, mut types) = (
            std::ptr::null_mut(),
            std::ptr::null_mut(),
            std::ptr::null_mut(),
        );
        // SAFETY: valid out-pointers; the arrays are CoTaskMem owned by us afterwards.
        unsafe {
            self.item_properties_itf()?.QueryAvailableProperties(
                PCWSTR(s.as_ptr()),
                &mut n,
                &mut ids,
                &mut descs,
                &mut types,
            )?
        };
        // SAFETY: a CoTaskMem array of that many elements, just handed out by the call.
        let ids = unsafe { take_array(ids, n as usize) };
        // SAFETY: a CoTaskMem array of that many elements, just handed out by the call.
        let descs: Vec<Option<String>> = unsafe { take_array(descs, n as usize) }
            .into_iter()
            // SAFETY: its elements are NULL or CoTaskMem strings, ours, each taken once.
            .map(|p| unsafe { take_wstr(p) })
            .collect();
        // SAFETY: a CoTaskMem array of that many elements, just handed out by the call.
        let types: Vec<VARTYPE> = unsafe { take_array(types, n as usize) };
        Ok(ids
            .into_iter()
            .zip(descs)
            .zip(types)
            .map(|((i, d), t)| (i, d, t.0))
            .collect())
    }

    /// GetItemProperties: (S_OK or S_FALSE, (value, error) per ID).
    pub fn get_item_properties(
        &self,
        item_id: &str,
        ids: &[u32],
    ) -> windows::core::Result<(HRESULT, Vec<(Value, HRESULT)>)> {
        let s = HSTRING::from(item_id);
        let (mut data, mut errors) = (std::ptr::null_mut(), std::ptr::null_mut());
        // SAFETY: `ids` holds `ids.len()` elements; valid out-pointers.
        let hr = ok_or_s_false(unsafe {
            self.item_properties_itf()?.GetItemProperties(
                PCWSTR(s.as_ptr()),
                ids.len() as u32,
                ids.as_ptr(),
                &mut data,
                &mut errors,
            )
        })?;
        // SAFETY: a CoTaskMem array of that many elements, just handed out by the call.
        let values = unsafe { take_variants(data, ids.len()) };
        // SAFETY: a CoTaskMem array of that many elements, just handed out by the call.
        let errors: Vec<HRESULT> = unsafe { take_array(errors, ids.len()) };
        Ok((hr, values.into_iter().map(|(_, v)| v).zip(errors).collect()))
    }

    /// LookupItemIDs: (S_OK or S_FALSE, (item ID, error) per ID).
    pub fn lookup_item_ids(
        &self,
        item_id: &str,
        ids: &[u32],
    ) -> windows::core::Result<(HRESULT, Vec<NewItemId>)> {
        let s = HSTRING::from(item_id);
        let (mut new_ids, mut errors) = (std::ptr::null_mut(), std::ptr::null_mut());
        // SAFETY: `ids` holds `ids.len()` elements; valid out-pointers.
        let hr = ok_or_s_false(unsafe {
            self.item_properties_itf()?.LookupItemIDs(
                PCWSTR(s.as_ptr()),
                ids.len() as u32,
                ids.as_ptr(),
                &mut new_ids,
                &mut errors,
            )
        })?;
        // SAFETY: a CoTaskMem array of that many elements, just handed out by the call.
        let new_ids: Vec<Option<String>> = unsafe { take_array(new_ids, ids.len()) }
            .into_iter()
            // SAFETY: its elements are NULL or CoTaskMem strings, ours, each taken once.
            .map(|p| unsafe { take_wstr(p) })
            .collect();
        // SAFETY: a CoTaskMem array of that many elements, just handed out by the call.
        let errors: Vec<HRESULT> = unsafe { take_array(errors, ids.len()) };
        Ok((hr, new_ids.into_iter().zip(errors).collect()))
    }

    // ---- IOPCBrowse ---------------------------------------------------------------------

    pub fn browse_itf(&self) -> windows::core::Result<IOPCBrowse> {
        self.unknown.cast()
    }

    /// IOPCBrowse::GetProperties: (S_OK or S_FALSE, one entry per item).
    pub fn get_properties(
        &self,
        item_ids: &[&str],
        values: bool,
        property_ids: &[u32],
    ) -> windows::core::Result<(HRESULT, Vec<ItemProperties>)> {
        let strings = WideStrings::new(item_ids);
        let ptrs = strings.pointers();
        let mut out: *mut OPCITEMPROPERTIES = std::ptr::null_mut();
        let dummy = 0u32;
        let pids = if property_ids.is_empty() {
            &dummy as *const u32
        } else {
            property_ids.as_ptr()
        };
        // SAFETY: the arrays hold the counts passed; valid out-pointer.
        let hr = ok_or_s_false(unsafe {
            self.browse_itf()?.GetProperties(
                ptrs.len() as u32,
                ptrs.as_ptr(),
                BOOL::from(values),
                property_ids.len() as u32,
                pids,
                &mut out,
            )
        })?;
        let mut result = Vec::new();
        if !out.is_null() {
            // SAFETY: the server allocated one OPCITEMPROPERTIES per item; each is taken
            // once, then the block is freed once.
            let items = unsafe { std::slice::from_raw_parts_mut(out, ptrs.len()) };
            result = items.iter_mut().map(take_item_properties).collect();
            // SAFETY: as above.
            unsafe { CoTaskMemFree(Some(out as *const c_void)) };
        }
        Ok((hr, result))
    }

    /// IOPCBrowse::Browse.
    pub fn browse(&self, a: &BrowseArgs) -> windows::core::Result<BrowsePage> {
        let item_id = HSTRING::from(a.item_id.as_str());
        let name_filter = HSTRING::from(a.name_filter.as_str());
        let vendor_filter = HSTRING::from(a.vendor_filter.as_str());
        let mut cp = match &a.continuation_point {
            Some(s) => ctopc_com::abi::alloc_wstr(s)?,
            None => PWSTR::null(),
        };
        let mut more = BOOL(0);
        let mut count = 0u32;
        let mut elements: *mut OPCBROWSEELEMENT = std::ptr::null_mut();
        let dummy = 0u32;
        let pids = if a.property_ids.is_empty() {
            &dummy as *const u32
        } else {
            a.property_ids.as_ptr()
        };
        // SAFETY: valid pointers for the call; `cp` is a CoTaskMem string (or NULL) that the
        // server may free and replace ([in, out]).
        let hr = unsafe {
            self.browse_itf()?.Browse(
                PCWSTR(item_id.as_ptr()),
                &mut cp,
                a.max_elements,
                OPCBROWSEFILTER(a.filter),
                PCWSTR(name_filter.as_ptr()),
                PCWSTR(vendor_filter.as_ptr()),
                BOOL::from(a.all_properties),
                BOOL::from(a.property_values),
                a.property_ids.len() as u32,
                pids,
                &mut more,
                &mut count,
                &mut elements,
            )
        };
        // SAFETY: NULL or the CoTaskMem continuation point the call handed out (it freed the
        // one passed in), ours.
        let continuation_point = unsafe { take_wstr(cp) };
        let _ = ok_or_s_false(hr)?;
        let mut out = Vec::new();
        if !elements.is_null() {
            // SAFETY: the server allocated `count` elements; each is taken once, then the
            // block is freed once.
            let slice = unsafe { std::slice::from_raw_parts_mut(elements, count as usize) };
            for e in slice.iter_mut() {
                out.push(BrowseElement {
                    // SAFETY: each element's strings are NULL or CoTaskMem, ours, taken
                    // once (see the slice above).
                    name: unsafe { take_wstr(e.szName) },
                    // SAFETY: as above.
                    item_id: unsafe { take_wstr(e.szItemID) },
                    flags: e.dwFlagValue,
                    properties: take_item_properties(&mut e.ItemProperties),
                });
            }
            // SAFETY: as above.
            unsafe { CoTaskMemFree(Some(elements as *const c_void)) };
        }
        Ok(BrowsePage {
            code: hr,
            continuation_point,
            more_elements: more.as_bool(),
            elements: out,
        })
    }

    // ---- IOPCItemIO ---------------------------------------------------------------------

    pub fn item_io(&self) -> windows::core::Result<IOPCItemIO> {
        self.unknown.cast()
    }

    /// IOPCItemIO::Read: (S_OK or S_FALSE, one item per `(item ID, MaxAge)`).
    pub fn item_read(
        &self,
        items: &[(&str, u32)],
    ) -> windows::core::Result<(HRESULT, Vec<ReadItem>)> {
        let ids: Vec<&str> = items.iter().map(|(id, _)| *id).collect();
        let strings = WideStrings::new(&ids);
        let ptrs = strings.pointers();
        let ages: Vec<u32> = items.iter().map(|(_, a)| *a).collect();
        let (mut values, mut qualities, mut times, mut errors) = (
            std::ptr::null_mut(),
            std::ptr::null_mut(),
            std::ptr::null_mut(),
            std::ptr::null_mut(),
        );
        // SAFETY: the arrays hold `items.len()` elements; valid out-pointers.
        let hr = ok_or_s_false(unsafe {
            self.item_io()?.Read(
                ptrs.len() as u32,
                ptrs.as_ptr(),
                ages.as_ptr(),
                &mut values,
                &mut qualities,
                &mut times,
                &mut errors,
            )
        })?;
        let n = items.len();
        // SAFETY: a CoTaskMem array of that many elements, just handed out by the call.
        let values = unsafe { take_variants(values, n) };
        // SAFETY: a CoTaskMem array of that many elements, just handed out by the call.
        let qualities: Vec<u16> = unsafe { take_array(qualities, n) };
        // SAFETY: a CoTaskMem array of that many elements, just handed out by the call.
        let times: Vec<FILETIME> = unsafe { take_array(times, n) };
        // SAFETY: a CoTaskMem array of that many elements, just handed out by the call.
        let errors: Vec<HRESULT> = unsafe { take_array(errors, n) };
        let out = (0..n)
            .map(|i| ReadItem {
                client_handle: 0,
                vt: values.get(i).map_or(0, |v| v.0),
                value: values.get(i).map_or(Value::Empty, |v| v.1.clone()),
                quality: qualities.get(i).copied().unwrap_or(0),
                timestamp: times.get(i).copied().map(timestamp).unwrap_or_default(),
                error: errors.get(i).copied().unwrap_or(HRESULT(0)),
            })
            .collect();
        Ok((hr, out))
    }

    /// IOPCItemIO::WriteVQT: (S_OK or S_FALSE, per-item codes).
    pub fn item_write_vqt(
        &self,
        items: &[(&str, ItemVqt)],
    ) -> windows::core::Result<(HRESULT, Vec<HRESULT>)> {
        let ids: Vec<&str> = items.iter().map(|(id, _)| *id).collect();
        let strings = WideStrings::new(&ids);
        let ptrs = strings.pointers();
        let mut vqts: Vec<OPCITEMVQT> = Vec::with_capacity(items.len());
        let mut result = Ok(());
        for (_, v) in items {
            match ctopc_com::variant::to_variant(&v.value) {
                Ok(value) => vqts.push(OPCITEMVQT {
                    vDataValue: value,
                    bQualitySpecified: BOOL::from(v.quality.is_some()),
                    wQuality: v.quality.map_or(0, |q| q.0),
                    wReserved: 0,
                    bTimeStampSpecified: BOOL::from(v.timestamp.is_some()),
                    dwReserved: 0,
                    ftTimeStamp: v
                        .timestamp
                        .map_or_else(FILETIME::default, ctopc_com::clock::filetime),
                }),
                Err(e) => {
                    result = Err(e);
                    break;
                }
            }
        }
        let call = result.and_then(|_| {
            let mut errors = std::ptr::null_mut();
            // SAFETY: the arrays hold `items.len()` elements; valid out-pointer.
            let hr = ok_or_s_false(unsafe {
                self.item_io()?.WriteVQT(
                    ptrs.len() as u32,
                    ptrs.as_ptr(),
                    vqts.as_ptr(),
                    &mut errors,
                )
            })?;
            // SAFETY: a CoTaskMem array of that many elements, just handed out by the call.
            Ok((hr, unsafe { take_array(errors, items.len()) }))
        });
        for v in &mut vqts {
            ctopc_com::variant::clear(&mut v.vDataValue);
        }
        call
    }

    // ---- IOPCShutdown connection point --------------------------------------------------

    /// Connects `sink` to the server's IOPCShutdown connection point; returns the cookie.
    pub fn advise_shutdown(&self, sink: &IOPCShutdown) -> windows::core::Result<u32> {
        let cpc: IConnectionPointContainer = self.unknown.cast()?;
        // SAFETY: a valid IID pointer for the call.
        let cp = unsafe { cpc.FindConnectionPoint(&IID_IOPCShutdown)? };
        // SAFETY: `sink` is a live interface pointer.
        unsafe { cp.Advise(&sink.cast::<IUnknown>()?) }
    }

    /// Disconnects the sink `advise_shutdown` connected.
    pub fn unadvise_shutdown(&self, cookie: u32) -> windows::core::Result<()> {
        let cpc: IConnectionPointContainer = self.unknown.cast()?;
        // SAFETY: a valid IID pointer for the call.
        let cp = unsafe { cpc.FindConnectionPoint(&IID_IOPCShutdown)? };
        // SAFETY: plain value.
        unsafe { cp.Unadvise(cookie) }
    }
}
