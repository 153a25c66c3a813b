//! Every error and success code the server can return, as a typed enum with its HRESULT value.
//! HRESULTs stay numbers here; the COM layer maps [`OpcError::hresult`] into `windows_core::Error`.

/// Result type of core operations.
pub type OpcResult<T> = Result<T, OpcError>;

macro_rules! codes {
    ($( $(#[$m:meta])* $name:ident = $val:literal, $sym:literal; )*) => {
        /// An OPC DA / OPC Common / COM / ASKOM code. Variant names are the symbolic names
        /// without prefix, in CamelCase (OPC_E_INVALIDHANDLE -> `InvalidHandle`).
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        pub enum OpcError {
            $( $(#[$m])* $name, )*
        }
        impl OpcError {
            /// Every code, in declaration order.
            pub const ALL: &'static [OpcError] = &[ $( OpcError::$name, )* ];
            /// The HRESULT value.
            pub const fn hresult(self) -> i32 {
                match self { $( OpcError::$name => $val as u32 as i32, )* }
            }
            /// The symbolic name as written in the specifications (e.g. "OPC_E_INVALIDHANDLE").
            pub const fn symbol(self) -> &'static str {
                match self { $( OpcError::$name => $sym, )* }
            }
            /// The code with this HRESULT value, if it is one of ours.
            pub fn from_hresult(hr: i32) -> Option<OpcError> {
                Self::ALL.iter().copied().find(|e| e.hresult() == hr)
            }
        }
    };
}

codes! {
    // OPC DA (opcerror.h)
    InvalidHandle = 0xC0040001u32, "OPC_E_INVALIDHANDLE";
    BadType = 0xC0040004u32, "OPC_E_BADTYPE";
    Public = 0xC0040005u32, "OPC_E_PUBLIC";
    BadRights = 0xC0040006u32, "OPC_E_BADRIGHTS";
    UnknownItemId = 0xC0040007u32, "OPC_E_UNKNOWNITEMID";
    InvalidItemId = 0xC0040008u32, "OPC_E_INVALIDITEMID";
    InvalidFilter = 0xC0040009u32, "OPC_E_INVALIDFILTER";
    UnknownPath = 0xC004000Au32, "OPC_E_UNKNOWNPATH";
    Range = 0xC004000Bu32, "OPC_E_RANGE";
    DuplicateName = 0xC004000Cu32, "OPC_E_DUPLICATENAME";
    UnsupportedRate = 0x0004000Du32, "OPC_S_UNSUPPORTEDRATE";
    Clamp = 0x0004000Eu32, "OPC_S_CLAMP";
    InUse = 0x0004000Fu32, "OPC_S_INUSE";
    InvalidConfigFile = 0xC0040010u32, "OPC_E_INVALIDCONFIGFILE";
    NotFound = 0xC0040011u32, "OPC_E_NOTFOUND";
    InvalidPid = 0xC0040203u32, "OPC_E_INVALID_PID";
    DeadbandNotSet = 0xC0040400u32, "OPC_E_DEADBANDNOTSET";
    DeadbandNotSupported = 0xC0040401u32, "OPC_E_DEADBANDNOTSUPPORTED";
    NoBuffering = 0xC0040402u32, "OPC_E_NOBUFFERING";
    InvalidContinuationPoint = 0xC0040403u32, "OPC_E_INVALIDCONTINUATIONPOINT";
    DataQueueOverflow = 0x00040404u32, "OPC_S_DATAQUEUEOVERFLOW";
    RateNotSet = 0xC0040405u32, "OPC_E_RATENOTSET";
    NotSupported = 0xC0040406u32, "OPC_E_NOTSUPPORTED";
    // COM / Win32 codes OPC methods return
    False = 0x00000001u32, "S_FALSE";
    Fail = 0x80004005u32, "E_FAIL";
    InvalidArg = 0x80070057u32, "E_INVALIDARG";
    OutOfMemory = 0x8007000Eu32, "E_OUTOFMEMORY";
    NotImpl = 0x80004001u32, "E_NOTIMPL";
    NoInterface = 0x80004002u32, "E_NOINTERFACE";
    Pointer = 0x80004003u32, "E_POINTER";
    AdviseLimit = 0x80040201u32, "CONNECT_E_ADVISELIMIT";
    NoConnection = 0x80040200u32, "CONNECT_E_NOCONNECTION";
    TypeMismatch = 0x80020005u32, "DISP_E_TYPEMISMATCH";
    Overflow = 0x8002000Au32, "DISP_E_OVERFLOW";
    // ASKOM (AsixConnect) network
    NetInit = 0xC0048100u32, "ASKOM_E_NetInit";
    NetInitTimeout = 0xC0048101u32, "ASKOM_E_NetInitTimeout";
    NetInstallClient = 0xC0048102u32, "ASKOM_E_NetInstallClient";
    NetDeinstallClient = 0xC0048103u32, "ASKOM_E_NetDeinstallClient";
    NetFindServer = 0xC0048104u32, "ASKOM_E_NetFindServer";
    NetFindServerNotFound = 0xC0048105u32, "ASKOM_E_NetFindServer_NotFound";
    NetLinkToServer = 0xC0048106u32, "ASKOM_E_NetLinkToServer";
    NetLinkToServerTimeout = 0xC0048107u32, "ASKOM_E_NetLinkToServerTimeout";
    NetLinkToServerNegativeAnswer = 0xC0048108u32, "ASKOM_E_NetLinkToServerNegativeAnswer";
    NetCloseLink = 0xC0048109u32, "ASKOM_E_NetCloseLink";
    NetSendData = 0xC004810Au32, "ASKOM_E_NetSendData";
    NetAnswerTimeout = 0xC004810Bu32, "ASKOM_E_NetAnswerTimeout";
    // ASKOM items and writes
    ItemUnknown = 0xC0048120u32, "ASKOM_E_ItemUnknown";
    TheSameItemWrittenMoreThanOnce = 0xC0048121u32, "ASKOM_E_TheSameItemWrittenMoreThanOnce";
    WriteError = 0xC0048128u32, "ASKOM_E_WriteError";
    WriteErrorNetworkServerNotFound = 0xC0048129u32, "ASKOM_E_WriteError_NetworkServerNotFound";
    WriteErrorIllegalCommand = 0xC004812Au32, "ASKOM_E_WriteError_IllegalCommand";
    WriteErrorDriverTimeout = 0xC004812Bu32, "ASKOM_E_WriteError_DriverTimeout";
    WriteErrorDriverTransmisionError = 0xC004812Cu32, "ASKOM_E_WriteError_DriverTransmisionError";
    WriteErrorDeviceRequestIllegal = 0xC004812Du32, "ASKOM_E_WriteError_DeviceRequestIllegal";
    GroupItemsCantBeUsed = 0xC0048139u32, "ASKOM_E_GroupItemsCantBeUsed";
    // ASKOM variable database
    VarBaseNotFound = 0xC004A001u32, "ASKOM_E_VarBaseNotFound";
    ErrorDuringOpeningVarBase = 0xC004A006u32, "ASKOM_E_ErrorDuringOpeningVarBase";
    ErrorDuringOpeningVarBaseSharedMemLocation = 0xC004A008u32, "ASKOM_E_ErrorDuringOpeningVarBase_SharedMemLocation";
}

impl OpcError {
    /// True for success codes (OPC_S_*, S_FALSE).
    pub const fn is_success(self) -> bool {
        self.hresult() >= 0
    }
}

impl std::fmt::Display for OpcError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} (0x{:08X})", self.symbol(), self.hresult() as u32)
    }
}

impl std::error::Error for OpcError {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_are_unique_and_round_trip() {
        for (i, a) in OpcError::ALL.iter().enumerate() {
            for b in &OpcError::ALL[i + 1..] {
                assert_ne!(a.hresult(), b.hresult(), "{a:?} and {b:?} share a value");
            }
            assert_eq!(OpcError::from_hresult(a.hresult()), Some(*a));
        }
        assert_eq!(OpcError::InvalidHandle.hresult() as u32, 0xC0040001);
        assert!(OpcError::UnsupportedRate.is_success());
        assert!(!OpcError::BadType.is_success());
    }
}
