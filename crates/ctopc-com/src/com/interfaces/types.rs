//! Types, enumerations and constants of the OPC Common 1.10 and OPC DA 2.05a/3.00 IDL
//! (`opccomn.idl`, `opcda.idl`), laid out exactly as MIDL lays them out.
//!
//! IDL enums are C `int`s: they are `#[repr(transparent)]` newtypes over `i32` here, in the
//! style of the `windows` crate (`VARENUM`, ...), so any value a client sends is representable.

use windows::Win32::Foundation::FILETIME;
use windows::Win32::System::Variant::{VARENUM, VARIANT};
use windows_core::{BOOL, GUID, HRESULT, PWSTR};

/// `OPCHANDLE`: a client or server handle (`typedef DWORD OPCHANDLE`).
pub type OPCHANDLE = u32;

/// `VARTYPE` (`unsigned short`), as the `windows` crate's `VARENUM` newtype.
pub type VARTYPE = VARENUM;

/// `LCID` (`DWORD`).
pub type LCID = u32;

macro_rules! idl_enum {
    ($(#[$doc:meta])* $name:ident { $($(#[$vdoc:meta])* $variant:ident = $value:expr),+ $(,)? }) => {
        $(#[$doc])*
        #[repr(transparent)]
        #[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
        pub struct $name(pub i32);
        $( $(#[$vdoc])* pub const $variant: $name = $name($value); )+
    };
}

idl_enum! {
    /// `OPCDATASOURCE`: where a synchronous read or a refresh takes its values from.
    OPCDATASOURCE { OPC_DS_CACHE = 1, OPC_DS_DEVICE = 2 }
}

idl_enum! {
    /// `OPCBROWSETYPE`: filter of `IOPCBrowseServerAddressSpace::BrowseOPCItemIDs`.
    OPCBROWSETYPE { OPC_BRANCH = 1, OPC_LEAF = 2, OPC_FLAT = 3 }
}

idl_enum! {
    /// `OPCNAMESPACETYPE` (the spec's spelling `HIERARCHIAL` is kept).
    OPCNAMESPACETYPE { OPC_NS_HIERARCHIAL = 1, OPC_NS_FLAT = 2 }
}

idl_enum! {
    /// `OPCBROWSEDIRECTION` of `IOPCBrowseServerAddressSpace::ChangeBrowsePosition`.
    OPCBROWSEDIRECTION { OPC_BROWSE_UP = 1, OPC_BROWSE_DOWN = 2, OPC_BROWSE_TO = 3 }
}

idl_enum! {
    /// `OPCEUTYPE`: engineering-units type of an item.
    OPCEUTYPE { OPC_NOENUM = 0, OPC_ANALOG = 1, OPC_ENUMERATED = 2 }
}

idl_enum! {
    /// `OPCSERVERSTATE` (`OPC_STATUS_COMM_FAULT` is new in DA 3.00).
    OPCSERVERSTATE {
        OPC_STATUS_RUNNING = 1,
        OPC_STATUS_FAILED = 2,
        OPC_STATUS_NOCONFIG = 3,
        OPC_STATUS_SUSPENDED = 4,
        OPC_STATUS_TEST = 5,
        OPC_STATUS_COMM_FAULT = 6,
    }
}

idl_enum! {
    /// `OPCENUMSCOPE` of `IOPCServer::CreateGroupEnumerator`.
    OPCENUMSCOPE {
        OPC_ENUM_PRIVATE_CONNECTIONS = 1,
        OPC_ENUM_PUBLIC_CONNECTIONS = 2,
        OPC_ENUM_ALL_CONNECTIONS = 3,
        OPC_ENUM_PRIVATE = 4,
        OPC_ENUM_PUBLIC = 5,
        OPC_ENUM_ALL = 6,
    }
}

idl_enum! {
    /// `OPCBROWSEFILTER` of `IOPCBrowse::Browse` (DA 3.00).
    OPCBROWSEFILTER {
        OPC_BROWSE_FILTER_ALL = 1,
        OPC_BROWSE_FILTER_BRANCHES = 2,
        OPC_BROWSE_FILTER_ITEMS = 3,
    }
}

// ---------------------------------------------------------------------------------------
// Structures. Field names are the IDL's; `#[repr(C)]` gives MIDL's /Zp8 layout.
// ---------------------------------------------------------------------------------------

/// `OPCGROUPHEADER` (DA 1.0 `IDataObject` stream format).
#[repr(C)]
#[allow(non_snake_case)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct OPCGROUPHEADER {
    pub dwSize: u32,
    pub dwItemCount: u32,
    pub hClientGroup: OPCHANDLE,
    pub dwTransactionID: u32,
    pub hrStatus: HRESULT,
}

/// `OPCITEMHEADER1` (DA 1.0 stream format, with time stamp).
#[repr(C)]
#[allow(non_snake_case)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct OPCITEMHEADER1 {
    pub hClient: OPCHANDLE,
    pub dwValueOffset: u32,
    pub wQuality: u16,
    pub wReserved: u16,
    pub ftTimeStampItem: FILETIME,
}

/// `OPCITEMHEADER2` (DA 1.0 stream format, without time stamp).
#[repr(C)]
#[allow(non_snake_case)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct OPCITEMHEADER2 {
    pub hClient: OPCHANDLE,
    pub dwValueOffset: u32,
    pub wQuality: u16,
    pub wReserved: u16,
}

/// `OPCGROUPHEADERWRITE` (DA 1.0 write-complete stream format).
#[repr(C)]
#[allow(non_snake_case)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct OPCGROUPHEADERWRITE {
    pub dwItemCount: u32,
    pub hClientGroup: OPCHANDLE,
    pub dwTransactionID: u32,
    pub hrStatus: HRESULT,
}

/// `OPCITEMHEADERWRITE` (DA 1.0 write-complete stream format).
#[repr(C)]
#[allow(non_snake_case)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct OPCITEMHEADERWRITE {
    pub hClient: OPCHANDLE,
    pub dwError: HRESULT,
}

/// `OPCITEMSTATE`: one value of `IOPCSyncIO::Read`. Owns its `VARIANT` (no `Drop`:
/// whoever frees the array must `VariantClear` each value).
#[repr(C)]
#[allow(non_snake_case)]
#[derive(Default)]
pub struct OPCITEMSTATE {
    pub hClient: OPCHANDLE,
    pub ftTimeStamp: FILETIME,
    pub wQuality: u16,
    pub wReserved: u16,
    pub vDataValue: VARIANT,
}

/// `OPCSERVERSTATUS` of `IOPCServer::GetStatus` (`szVendorInfo` is CoTaskMem-allocated).
#[repr(C)]
#[allow(non_snake_case)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct OPCSERVERSTATUS {
    pub ftStartTime: FILETIME,
    pub ftCurrentTime: FILETIME,
    pub ftLastUpdateTime: FILETIME,
    pub dwServerState: OPCSERVERSTATE,
    pub dwGroupCount: u32,
    pub dwBandWidth: u32,
    pub wMajorVersion: u16,
    pub wMinorVersion: u16,
    pub wBuildNumber: u16,
    pub wReserved: u16,
    pub szVendorInfo: PWSTR,
}

/// `OPCITEMDEF`: one item of `IOPCItemMgt::AddItems`/`ValidateItems` (client-owned).
#[repr(C)]
#[allow(non_snake_case)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OPCITEMDEF {
    pub szAccessPath: PWSTR,
    pub szItemID: PWSTR,
    pub bActive: BOOL,
    pub hClient: OPCHANDLE,
    pub dwBlobSize: u32,
    pub pBlob: *mut u8,
    pub vtRequestedDataType: VARTYPE,
    pub wReserved: u16,
}

impl Default for OPCITEMDEF {
    fn default() -> Self {
        Self {
            szAccessPath: PWSTR::null(),
            szItemID: PWSTR::null(),
            bActive: BOOL(0),
            hClient: 0,
            dwBlobSize: 0,
            pBlob: core::ptr::null_mut(),
            vtRequestedDataType: VARENUM(0),
            wReserved: 0,
        }
    }
}

/// `OPCITEMATTRIBUTES`: one element of `IEnumOPCItemAttributes::Next`.
#[repr(C)]
#[allow(non_snake_case)]
pub struct OPCITEMATTRIBUTES {
    pub szAccessPath: PWSTR,
    pub szItemID: PWSTR,
    pub bActive: BOOL,
    pub hClient: OPCHANDLE,
    pub hServer: OPCHANDLE,
    pub dwAccessRights: u32,
    pub dwBlobSize: u32,
    pub pBlob: *mut u8,
    pub vtRequestedDataType: VARTYPE,
    pub vtCanonicalDataType: VARTYPE,
    pub dwEUType: OPCEUTYPE,
    pub vEUInfo: VARIANT,
}

impl Default for OPCITEMATTRIBUTES {
    fn default() -> Self {
        Self {
            szAccessPath: PWSTR::null(),
            szItemID: PWSTR::null(),
            bActive: BOOL(0),
            hClient: 0,
            hServer: 0,
            dwAccessRights: 0,
            dwBlobSize: 0,
            pBlob: core::ptr::null_mut(),
            vtRequestedDataType: VARENUM(0),
            vtCanonicalDataType: VARENUM(0),
            dwEUType: OPC_NOENUM,
            vEUInfo: VARIANT::default(),
        }
    }
}

/// `OPCITEMRESULT`: one result of `IOPCItemMgt::AddItems`/`ValidateItems`.
#[repr(C)]
#[allow(non_snake_case)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct OPCITEMRESULT {
    pub hServer: OPCHANDLE,
    pub vtCanonicalDataType: VARTYPE,
    pub wReserved: u16,
    pub dwAccessRights: u32,
    pub dwBlobSize: u32,
    pub pBlob: *mut u8,
}

impl Default for OPCITEMRESULT {
    fn default() -> Self {
        Self {
            hServer: 0,
            vtCanonicalDataType: VARENUM(0),
            wReserved: 0,
            dwAccessRights: 0,
            dwBlobSize: 0,
            pBlob: core::ptr::null_mut(),
        }
    }
}

/// `OPCITEMPROPERTY` (DA 3.00): one property in an [`OPCITEMPROPERTIES`].
#[repr(C)]
#[allow(non_snake_case)]
#[derive(Default)]
pub struct OPCITEMPROPERTY {
    pub vtDataType: VARTYPE,
    pub wReserved: u16,
    pub dwPropertyID: u32,
    pub szItemID: PWSTR,
    pub szDescription: PWSTR,
    pub vValue: VARIANT,
    pub hrErrorID: HRESULT,
    pub dwReserved: u32,
}

/// `OPCITEMPROPERTIES` (DA 3.00): the properties of one item (`IOPCBrowse`).
#[repr(C)]
#[allow(non_snake_case)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct OPCITEMPROPERTIES {
    pub hrErrorID: HRESULT,
    pub dwNumProperties: u32,
    pub pItemProperties: *mut OPCITEMPROPERTY,
    pub dwReserved: u32,
}

impl Default for OPCITEMPROPERTIES {
    fn default() -> Self {
        Self {
            hrErrorID: HRESULT(0),
            dwNumProperties: 0,
            pItemProperties: core::ptr::null_mut(),
            dwReserved: 0,
        }
    }
}

/// `OPCBROWSEELEMENT` (DA 3.00): one element returned by `IOPCBrowse::Browse`.
#[repr(C)]
#[allow(non_snake_case)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct OPCBROWSEELEMENT {
    pub szName: PWSTR,
    pub szItemID: PWSTR,
    pub dwFlagValue: u32,
    pub dwReserved: u32,
    pub ItemProperties: OPCITEMPROPERTIES,
}

/// `OPCITEMVQT` (DA 3.00): value, optional quality, optional time stamp of a `WriteVQT`.
#[repr(C)]
#[allow(non_snake_case)]
#[derive(Default)]
pub struct OPCITEMVQT {
    pub vDataValue: VARIANT,
    pub bQualitySpecified: BOOL,
    pub wQuality: u16,
    pub wReserved: u16,
    pub bTimeStampSpecified: BOOL,
    pub dwReserved: u32,
    pub ftTimeStamp: FILETIME,
}

// Layouts as MIDL's /Zp8 computes them for 64-bit Windows: a wrong field type or order
// fails the build rather than corrupting memory at run time.
#[cfg(target_pointer_width = "64")]
const _: () = {
    use core::mem::size_of;
    assert!(size_of::<VARIANT>() == 24);
    assert!(size_of::<OPCGROUPHEADER>() == 20);
    assert!(size_of::<OPCITEMHEADER1>() == 20);
    assert!(size_of::<OPCITEMHEADER2>() == 12);
    assert!(size_of::<OPCGROUPHEADERWRITE>() == 16);
    assert!(size_of::<OPCITEMHEADERWRITE>() == 8);
    assert!(size_of::<OPCITEMSTATE>() == 40);
    assert!(size_of::<OPCSERVERSTATUS>() == 56);
    assert!(size_of::<OPCITEMDEF>() == 48);
    assert!(size_of::<OPCITEMATTRIBUTES>() == 80);
    assert!(size_of::<OPCITEMRESULT>() == 24);
    assert!(size_of::<OPCITEMPROPERTY>() == 56);
    assert!(size_of::<OPCITEMPROPERTIES>() == 24);
    assert!(size_of::<OPCBROWSEELEMENT>() == 48);
    assert!(size_of::<OPCITEMVQT>() == 48);
};

// ---------------------------------------------------------------------------------------
// Component categories (opcda.idl: `CATID_OPCDAServer10` ... as `IID_CATID_...`).
// ---------------------------------------------------------------------------------------

/// `CATID_OPCDAServer10`: "OPC Data Access Servers Version 1.0".
pub const CATID_OPCDAServer10: GUID = GUID::from_u128(0x63d5f430_cfe4_11d1_b2c8_0060083ba1fb);
/// `CATID_OPCDAServer20`: "OPC Data Access Servers Version 2.0".
pub const CATID_OPCDAServer20: GUID = GUID::from_u128(0x63d5f432_cfe4_11d1_b2c8_0060083ba1fb);
/// `CATID_OPCDAServer30`: "OPC Data Access Servers Version 3.0".
pub const CATID_OPCDAServer30: GUID = GUID::from_u128(0xcc603642_66d7_48f1_b69a_b625e73652d7);
/// `CATID_XMLDAServer10`: "OPC XML Data Access Servers Version 1.0" (not implemented here).
pub const CATID_XMLDAServer10: GUID = GUID::from_u128(0x3098eda4_a006_48b2_a27f_247453959408);

/// `CLSID_OpcServerList`: the OPC Foundation's OPCEnum (`OPC.ServerList.1`).
pub const CLSID_OpcServerList: GUID = GUID::from_u128(0x13486d51_4821_11d2_a494_3cb306c10000);

/// Category descriptions to register with `ICatRegister::RegisterCategories`.
pub const OPC_CATEGORY_DESCRIPTION_DA10: &str = "OPC Data Access Servers Version 1.0";
pub const OPC_CATEGORY_DESCRIPTION_DA20: &str = "OPC Data Access Servers Version 2.0";
pub const OPC_CATEGORY_DESCRIPTION_DA30: &str = "OPC Data Access Servers Version 3.0";
pub const OPC_CATEGORY_DESCRIPTION_XMLDA10: &str = "OPC XML Data Access Servers Version 1.0";

// ---------------------------------------------------------------------------------------
// OPCDA_Constants
// ---------------------------------------------------------------------------------------

/// Access rights (`dwAccessRights`).
pub const OPC_READABLE: u32 = 0x1;
pub const OPC_WRITEABLE: u32 = 0x2;

/// `OPCBROWSEELEMENT::dwFlagValue` bits.
pub const OPC_BROWSE_HASCHILDREN: u32 = 0x1;
pub const OPC_BROWSE_ISITEM: u32 = 0x2;

pub const OPC_TYPE_SYSTEM_OPCBINARY: &str = "OPCBinary";
pub const OPC_TYPE_SYSTEM_XMLSCHEMA: &str = "XMLSchema";
pub const OPC_CONSISTENCY_WINDOW_UNKNOWN: &str = "Unknown";
pub const OPC_CONSISTENCY_WINDOW_NOT_CONSISTENT: &str = "Not Consistent";
pub const OPC_WRITE_BEHAVIOR_BEST_EFFORT: &str = "Best Effort";
pub const OPC_WRITE_BEHAVIOR_ALL_OR_NOTHING: &str = "All or Nothing";

// ---------------------------------------------------------------------------------------
// OPCDA_Qualities (`wQuality`: QQSSSSLL)
// ---------------------------------------------------------------------------------------

pub const OPC_QUALITY_MASK: u16 = 0xC0;
pub const OPC_STATUS_MASK: u16 = 0xFC;
pub const OPC_LIMIT_MASK: u16 = 0x03;

pub const OPC_QUALITY_BAD: u16 = 0x00;
pub const OPC_QUALITY_UNCERTAIN: u16 = 0x40;
pub const OPC_QUALITY_GOOD: u16 = 0xC0;

// Substatus for BAD quality.
pub const OPC_QUALITY_CONFIG_ERROR: u16 = 0x04;
pub const OPC_QUALITY_NOT_CONNECTED: u16 = 0x08;
pub const OPC_QUALITY_DEVICE_FAILURE: u16 = 0x0C;
pub const OPC_QUALITY_SENSOR_FAILURE: u16 = 0x10;
pub const OPC_QUALITY_LAST_KNOWN: u16 = 0x14;
pub const OPC_QUALITY_COMM_FAILURE: u16 = 0x18;
pub const OPC_QUALITY_OUT_OF_SERVICE: u16 = 0x1C;
pub const OPC_QUALITY_WAITING_FOR_INITIAL_DATA: u16 = 0x20;

// Substatus for UNCERTAIN quality.
pub const OPC_QUALITY_LAST_USABLE: u16 = 0x44;
pub const OPC_QUALITY_SENSOR_CAL: u16 = 0x50;
pub const OPC_QUALITY_EGU_EXCEEDED: u16 = 0x54;
pub const OPC_QUALITY_SUB_NORMAL: u16 = 0x58;

// Substatus for GOOD quality.
pub const OPC_QUALITY_LOCAL_OVERRIDE: u16 = 0xD8;

// Limit status.
pub const OPC_LIMIT_OK: u16 = 0x00;
pub const OPC_LIMIT_LOW: u16 = 0x01;
pub const OPC_LIMIT_HIGH: u16 = 0x02;
pub const OPC_LIMIT_CONST: u16 = 0x03;

// ---------------------------------------------------------------------------------------
// OPCDA_Properties: item property IDs and their standard descriptions.
// ---------------------------------------------------------------------------------------

pub const OPC_PROPERTY_DATATYPE: u32 = 1;
pub const OPC_PROPERTY_VALUE: u32 = 2;
pub const OPC_PROPERTY_QUALITY: u32 = 3;
pub const OPC_PROPERTY_TIMESTAMP: u32 = 4;
pub const OPC_PROPERTY_ACCESS_RIGHTS: u32 = 5;
pub const OPC_PROPERTY_SCAN_RATE: u32 = 6;
pub const OPC_PROPERTY_EU_TYPE: u32 = 7;
pub const OPC_PROPERTY_EU_INFO: u32 = 8;
pub const OPC_PROPERTY_EU_UNITS: u32 = 100;
pub const OPC_PROPERTY_DESCRIPTION: u32 = 101;
pub const OPC_PROPERTY_HIGH_EU: u32 = 102;
pub const OPC_PROPERTY_LOW_EU: u32 = 103;
pub const OPC_PROPERTY_HIGH_IR: u32 = 104;
pub const OPC_PROPERTY_LOW_IR: u32 = 105;
pub const OPC_PROPERTY_CLOSE_LABEL: u32 = 106;
pub const OPC_PROPERTY_OPEN_LABEL: u32 = 107;
pub const OPC_PROPERTY_TIMEZONE: u32 = 108;
pub const OPC_PROPERTY_CONDITION_STATUS: u32 = 300;
pub const OPC_PROPERTY_ALARM_QUICK_HELP: u32 = 301;
pub const OPC_PROPERTY_ALARM_AREA_LIST: u32 = 302;
pub const OPC_PROPERTY_PRIMARY_ALARM_AREA: u32 = 303;
pub const OPC_PROPERTY_CONDITION_LOGIC: u32 = 304;
pub const OPC_PROPERTY_LIMIT_EXCEEDED: u32 = 305;
pub const OPC_PROPERTY_DEADBAND: u32 = 306;
pub const OPC_PROPERTY_HIHI_LIMIT: u32 = 307;
pub const OPC_PROPERTY_HI_LIMIT: u32 = 308;
pub const OPC_PROPERTY_LO_LIMIT: u32 = 309;
pub const OPC_PROPERTY_LOLO_LIMIT: u32 = 310;
pub const OPC_PROPERTY_CHANGE_RATE_LIMIT: u32 = 311;
pub const OPC_PROPERTY_DEVIATION_LIMIT: u32 = 312;
pub const OPC_PROPERTY_SOUND_FILE: u32 = 313;
pub const OPC_PROPERTY_TYPE_SYSTEM_ID: u32 = 600;
pub const OPC_PROPERTY_DICTIONARY_ID: u32 = 601;
pub const OPC_PROPERTY_TYPE_ID: u32 = 602;
pub const OPC_PROPERTY_DICTIONARY: u32 = 603;
pub const OPC_PROPERTY_TYPE_DESCRIPTION: u32 = 604;
pub const OPC_PROPERTY_CONSISTENCY_WINDOW: u32 = 605;
pub const OPC_PROPERTY_WRITE_BEHAVIOR: u32 = 606;
pub const OPC_PROPERTY_UNCONVERTED_ITEM_ID: u32 = 607;
pub const OPC_PROPERTY_UNFILTERED_ITEM_ID: u32 = 608;
pub const OPC_PROPERTY_DATA_FILTER_VALUE: u32 = 609;

pub const OPC_PROPERTY_DESC_DATATYPE: &str = "Item Canonical Data Type";
pub const OPC_PROPERTY_DESC_VALUE: &str = "Item Value";
pub const OPC_PROPERTY_DESC_QUALITY: &str = "Item Quality";
pub const OPC_PROPERTY_DESC_TIMESTAMP: &str = "Item Timestamp";
pub const OPC_PROPERTY_DESC_ACCESS_RIGHTS: &str = "Item Access Rights";
pub const OPC_PROPERTY_DESC_SCAN_RATE: &str = "Server Scan Rate";
pub const OPC_PROPERTY_DESC_EU_TYPE: &str = "Item EU Type";
pub const OPC_PROPERTY_DESC_EU_INFO: &str = "Item EU Info";
pub const OPC_PROPERTY_DESC_EU_UNITS: &str = "EU Units";
pub const OPC_PROPERTY_DESC_DESCRIPTION: &str = "Item Description";
pub const OPC_PROPERTY_DESC_HIGH_EU: &str = "High EU";
pub const OPC_PROPERTY_DESC_LOW_EU: &str = "Low EU";
pub const OPC_PROPERTY_DESC_HIGH_IR: &str = "High Instrument Range";
pub const OPC_PROPERTY_DESC_LOW_IR: &str = "Low Instrument Range";
pub const OPC_PROPERTY_DESC_CLOSE_LABEL: &str = "Contact Close Label";
pub const OPC_PROPERTY_DESC_OPEN_LABEL: &str = "Contact Open Label";
pub const OPC_PROPERTY_DESC_TIMEZONE: &str = "Item Timezone";
pub const OPC_PROPERTY_DESC_CONDITION_STATUS: &str = "Condition Status";
pub const OPC_PROPERTY_DESC_ALARM_QUICK_HELP: &str = "Alarm Quick Help";
pub const OPC_PROPERTY_DESC_ALARM_AREA_LIST: &str = "Alarm Area List";
pub const OPC_PROPERTY_DESC_PRIMARY_ALARM_AREA: &str = "Primary Alarm Area";
pub const OPC_PROPERTY_DESC_CONDITION_LOGIC: &str = "Condition Logic";
pub const OPC_PROPERTY_DESC_LIMIT_EXCEEDED: &str = "Limit Exceeded";
pub const OPC_PROPERTY_DESC_DEADBAND: &str = "Deadband";
pub const OPC_PROPERTY_DESC_HIHI_LIMIT: &str = "HiHi Limit";
pub const OPC_PROPERTY_DESC_HI_LIMIT: &str = "Hi Limit";
pub const OPC_PROPERTY_DESC_LO_LIMIT: &str = "Lo Limit";
pub const OPC_PROPERTY_DESC_LOLO_LIMIT: &str = "LoLo Limit";
pub const OPC_PROPERTY_DESC_CHANGE_RATE_LIMIT: &str = "Rate of Change Limit";
pub const OPC_PROPERTY_DESC_DEVIATION_LIMIT: &str = "Deviation Limit";
pub const OPC_PROPERTY_DESC_SOUND_FILE: &str = "Sound File";
pub const OPC_PROPERTY_DESC_TYPE_SYSTEM_ID: &str = "Type System ID";
pub const OPC_PROPERTY_DESC_DICTIONARY_ID: &str = "Dictionary ID";
pub const OPC_PROPERTY_DESC_TYPE_ID: &str = "Type ID";
pub const OPC_PROPERTY_DESC_DICTIONARY: &str = "Dictionary";
pub const OPC_PROPERTY_DESC_TYPE_DESCRIPTION: &str = "Type Description";
pub const OPC_PROPERTY_DESC_CONSISTENCY_WINDOW: &str = "Consistency Window";
pub const OPC_PROPERTY_DESC_WRITE_BEHAVIOR: &str = "Write Behavior";
pub const OPC_PROPERTY_DESC_UNCONVERTED_ITEM_ID: &str = "Unconverted Item ID";
pub const OPC_PROPERTY_DESC_UNFILTERED_ITEM_ID: &str = "Unfiltered Item ID";
pub const OPC_PROPERTY_DESC_DATA_FILTER_VALUE: &str = "Data Filter Value";
