//! Every error and success code the server can return, as a typed enum with its HRESULT value.
//! HRESULTs stay numbers here; the COM layer maps [`OpcError::hresult`] into `windows_core::Error`.
//!
//! Each code carries its message in English and Polish ([`OpcError::text`]), as
//! IOPCCommon::GetErrorString returns it for the client's locale. OPC codes follow the OPC
//! Foundation's texts (opcerror.h); ASKOM codes are worded after their symbolic names.

use crate::lang::Lang;

/// Result type of core operations.
pub type OpcResult<T> = Result<T, OpcError>;

macro_rules! codes {
    ($( $(#[$m:meta])* $name:ident = $val:literal, $sym:literal, $en:literal, $pl:literal; )*) => {
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
            /// The message for this code in `lang` (IOPCCommon::GetErrorString).
            pub const fn text(self, lang: Lang) -> &'static str {
                match lang {
                    Lang::English => match self { $( OpcError::$name => $en, )* },
                    Lang::Polish => match self { $( OpcError::$name => $pl, )* },
                }
            }
        }
    };
}

codes! {
    // OPC DA (opcerror.h)
    InvalidHandle = 0xC0040001u32, "OPC_E_INVALIDHANDLE",
        "The value of the handle is invalid.",
        "Wartość uchwytu jest nieprawidłowa.";
    BadType = 0xC0040004u32, "OPC_E_BADTYPE",
        "The server cannot convert the data between the requested data type and the canonical data type.",
        "Serwer nie może przekształcić danych między żądanym typem danych a typem kanonicznym.";
    Public = 0xC0040005u32, "OPC_E_PUBLIC",
        "The requested operation cannot be done on a public group.",
        "Żądanej operacji nie można wykonać na grupie publicznej.";
    BadRights = 0xC0040006u32, "OPC_E_BADRIGHTS",
        "The item's access rights do not allow the operation.",
        "Prawa dostępu do elementu nie pozwalają na tę operację.";
    UnknownItemId = 0xC0040007u32, "OPC_E_UNKNOWNITEMID",
        "The item ID is not defined in the server address space or no longer exists in it.",
        "Identyfikator elementu nie jest zdefiniowany w przestrzeni adresowej serwera lub już w niej nie istnieje.";
    InvalidItemId = 0xC0040008u32, "OPC_E_INVALIDITEMID",
        "The item ID does not conform to the server's syntax.",
        "Identyfikator elementu jest niezgodny ze składnią serwera.";
    InvalidFilter = 0xC0040009u32, "OPC_E_INVALIDFILTER",
        "The filter string is not valid.",
        "Ciąg filtru jest nieprawidłowy.";
    UnknownPath = 0xC004000Au32, "OPC_E_UNKNOWNPATH",
        "The item's access path is not known to the server.",
        "Ścieżka dostępu elementu jest nieznana serwerowi.";
    Range = 0xC004000Bu32, "OPC_E_RANGE",
        "The value is out of range.",
        "Wartość jest poza zakresem.";
    DuplicateName = 0xC004000Cu32, "OPC_E_DUPLICATENAME",
        "Duplicate name not allowed.",
        "Powtórzona nazwa jest niedozwolona.";
    UnsupportedRate = 0x0004000Du32, "OPC_S_UNSUPPORTEDRATE",
        "The server does not support the requested rate but will use the closest available rate.",
        "Serwer nie obsługuje żądanej częstotliwości, ale użyje najbliższej dostępnej.";
    Clamp = 0x0004000Eu32, "OPC_S_CLAMP",
        "A value passed to write was accepted but the output was clamped.",
        "Wartość przekazana do zapisu została przyjęta, ale wyjście zostało ograniczone.";
    InUse = 0x0004000Fu32, "OPC_S_INUSE",
        "The operation cannot be performed because the object is being referenced.",
        "Nie można wykonać operacji, ponieważ obiekt jest używany.";
    InvalidConfigFile = 0xC0040010u32, "OPC_E_INVALIDCONFIGFILE",
        "The server's configuration file has an invalid format.",
        "Plik konfiguracyjny serwera ma nieprawidłowy format.";
    NotFound = 0xC0040011u32, "OPC_E_NOTFOUND",
        "The requested object (e.g. a public group) was not found.",
        "Nie znaleziono żądanego obiektu (np. grupy publicznej).";
    InvalidPid = 0xC0040203u32, "OPC_E_INVALID_PID",
        "The specified property ID is not valid for the item.",
        "Podany identyfikator właściwości jest nieprawidłowy dla tego elementu.";
    DeadbandNotSet = 0xC0040400u32, "OPC_E_DEADBANDNOTSET",
        "The item deadband has not been set for this item.",
        "Dla tego elementu nie ustawiono strefy nieczułości.";
    DeadbandNotSupported = 0xC0040401u32, "OPC_E_DEADBANDNOTSUPPORTED",
        "The item does not support deadband.",
        "Element nie obsługuje strefy nieczułości.";
    NoBuffering = 0xC0040402u32, "OPC_E_NOBUFFERING",
        "The server does not support buffering of data items that are collected at a faster rate than the group update rate.",
        "Serwer nie obsługuje buforowania danych zbieranych szybciej, niż wynosi częstotliwość odświeżania grupy.";
    InvalidContinuationPoint = 0xC0040403u32, "OPC_E_INVALIDCONTINUATIONPOINT",
        "The continuation point is not valid.",
        "Punkt kontynuacji jest nieprawidłowy.";
    DataQueueOverflow = 0x00040404u32, "OPC_S_DATAQUEUEOVERFLOW",
        "Not every detected change has been returned because the server's buffer reached its limit and the oldest data had to be purged.",
        "Nie zwrócono wszystkich wykrytych zmian, ponieważ bufor serwera osiągnął limit i najstarsze dane zostały usunięte.";
    RateNotSet = 0xC0040405u32, "OPC_E_RATENOTSET",
        "There is no sampling rate set for the specified item.",
        "Dla podanego elementu nie ustawiono częstotliwości próbkowania.";
    NotSupported = 0xC0040406u32, "OPC_E_NOTSUPPORTED",
        "The server does not support writing of quality and/or timestamp.",
        "Serwer nie obsługuje zapisu jakości i/lub znacznika czasu.";
    // COM / Win32 codes OPC methods return
    False = 0x00000001u32, "S_FALSE",
        "The operation completed, but at least one item failed.",
        "Operacja została wykonana, ale co najmniej jeden element zakończył się błędem.";
    Fail = 0x80004005u32, "E_FAIL",
        "Unspecified error.",
        "Nieokreślony błąd.";
    InvalidArg = 0x80070057u32, "E_INVALIDARG",
        "One or more arguments are invalid.",
        "Co najmniej jeden argument jest nieprawidłowy.";
    OutOfMemory = 0x8007000Eu32, "E_OUTOFMEMORY",
        "Not enough memory to complete the operation.",
        "Za mało pamięci, aby wykonać operację.";
    NotImpl = 0x80004001u32, "E_NOTIMPL",
        "Not implemented.",
        "Funkcja nie została zaimplementowana.";
    NoInterface = 0x80004002u32, "E_NOINTERFACE",
        "No such interface supported.",
        "Interfejs nie jest obsługiwany.";
    Pointer = 0x80004003u32, "E_POINTER",
        "Invalid pointer.",
        "Nieprawidłowy wskaźnik.";
    AdviseLimit = 0x80040201u32, "CONNECT_E_ADVISELIMIT",
        "The advise limit has been reached; no further connections are allowed.",
        "Osiągnięto limit połączeń; kolejne połączenia są niedozwolone.";
    NoConnection = 0x80040200u32, "CONNECT_E_NOCONNECTION",
        "There is no connection for this connection ID.",
        "Nie ma połączenia o podanym identyfikatorze.";
    TypeMismatch = 0x80020005u32, "DISP_E_TYPEMISMATCH",
        "Type mismatch: the value cannot be converted to the requested type.",
        "Niezgodność typów: nie można przekształcić wartości do żądanego typu.";
    Overflow = 0x8002000Au32, "DISP_E_OVERFLOW",
        "The value does not fit in the requested type (out of present range).",
        "Wartość nie mieści się w zakresie żądanego typu.";
    BadVarType = 0x80020008u32, "DISP_E_BADVARTYPE",
        "The variant type is not a valid type.",
        "Typ wariantu jest nieprawidłowy.";
    // ASKOM (AsixConnect) network
    NetInit = 0xC0048100u32, "ASKOM_E_NetInit",
        "Initialising the asix network failed.",
        "Błąd inicjalizacji sieci asix.";
    NetInitTimeout = 0xC0048101u32, "ASKOM_E_NetInitTimeout",
        "Initialising the asix network timed out.",
        "Przekroczono czas inicjalizacji sieci asix.";
    NetInstallClient = 0xC0048102u32, "ASKOM_E_NetInstallClient",
        "Registering the client in the asix network failed.",
        "Błąd rejestracji klienta w sieci asix.";
    NetDeinstallClient = 0xC0048103u32, "ASKOM_E_NetDeinstallClient",
        "Unregistering the client from the asix network failed.",
        "Błąd wyrejestrowania klienta z sieci asix.";
    NetFindServer = 0xC0048104u32, "ASKOM_E_NetFindServer",
        "Searching for an asix server failed.",
        "Błąd wyszukiwania serwera asix.";
    NetFindServerNotFound = 0xC0048105u32, "ASKOM_E_NetFindServer_NotFound",
        "No asix server offering the resource was found.",
        "Nie znaleziono serwera asix udostępniającego zasób.";
    NetLinkToServer = 0xC0048106u32, "ASKOM_E_NetLinkToServer",
        "Connecting to the asix server failed.",
        "Błąd połączenia z serwerem asix.";
    NetLinkToServerTimeout = 0xC0048107u32, "ASKOM_E_NetLinkToServerTimeout",
        "Connecting to the asix server timed out.",
        "Przekroczono czas oczekiwania na połączenie z serwerem asix.";
    NetLinkToServerNegativeAnswer = 0xC0048108u32, "ASKOM_E_NetLinkToServerNegativeAnswer",
        "The asix server refused the connection.",
        "Serwer asix odmówił połączenia.";
    NetCloseLink = 0xC0048109u32, "ASKOM_E_NetCloseLink",
        "Closing the connection to the asix server failed.",
        "Błąd zamykania połączenia z serwerem asix.";
    NetSendData = 0xC004810Au32, "ASKOM_E_NetSendData",
        "Sending data to the asix server failed.",
        "Błąd wysyłania danych do serwera asix.";
    NetAnswerTimeout = 0xC004810Bu32, "ASKOM_E_NetAnswerTimeout",
        "The asix server did not answer in time.",
        "Przekroczono czas oczekiwania na odpowiedź serwera asix.";
    // ASKOM items and writes
    ItemUnknown = 0xC0048120u32, "ASKOM_E_ItemUnknown",
        "The asix server does not know the variable.",
        "Serwer asix nie zna zmiennej.";
    TheSameItemWrittenMoreThanOnce = 0xC0048121u32, "ASKOM_E_TheSameItemWrittenMoreThanOnce",
        "The same item was written more than once in one request.",
        "Ten sam element zapisano więcej niż raz w jednym żądaniu.";
    WriteError = 0xC0048128u32, "ASKOM_E_WriteError",
        "Write error.",
        "Błąd zapisu.";
    WriteErrorNetworkServerNotFound = 0xC0048129u32, "ASKOM_E_WriteError_NetworkServerNotFound",
        "Write error: the asix network server was not found.",
        "Błąd zapisu: nie znaleziono serwera sieciowego asix.";
    WriteErrorIllegalCommand = 0xC004812Au32, "ASKOM_E_WriteError_IllegalCommand",
        "Write error: illegal command.",
        "Błąd zapisu: niedozwolone polecenie.";
    WriteErrorDriverTimeout = 0xC004812Bu32, "ASKOM_E_WriteError_DriverTimeout",
        "Write error: the driver did not answer in time.",
        "Błąd zapisu: przekroczono czas oczekiwania na odpowiedź drajwera.";
    WriteErrorDriverTransmisionError = 0xC004812Cu32, "ASKOM_E_WriteError_DriverTransmisionError",
        "Write error: driver transmission error.",
        "Błąd zapisu: błąd transmisji drajwera.";
    WriteErrorDeviceRequestIllegal = 0xC004812Du32, "ASKOM_E_WriteError_DeviceRequestIllegal",
        "Write error: the device rejected the request as illegal.",
        "Błąd zapisu: urządzenie odrzuciło żądanie jako niedozwolone.";
    GroupItemsCantBeUsed = 0xC0048139u32, "ASKOM_E_GroupItemsCantBeUsed",
        "Group items cannot be used in this operation.",
        "W tej operacji nie można używać elementów grupowych.";
    // ASKOM variable database
    VarBaseNotFound = 0xC004A001u32, "ASKOM_E_VarBaseNotFound",
        "The variable database was not found.",
        "Nie znaleziono bazy zmiennych.";
    ErrorDuringOpeningVarBase = 0xC004A006u32, "ASKOM_E_ErrorDuringOpeningVarBase",
        "Error while opening the variable database.",
        "Błąd podczas otwierania bazy zmiennych.";
    ErrorDuringOpeningVarBaseSharedMemLocation = 0xC004A008u32, "ASKOM_E_ErrorDuringOpeningVarBase_SharedMemLocation",
        "Error while opening the variable database: the shared memory could not be located.",
        "Błąd podczas otwierania bazy zmiennych: nie można zlokalizować pamięci współdzielonej.";
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

    #[test]
    fn every_code_has_distinct_texts_in_both_languages() {
        for lang in Lang::ALL {
            let mut seen = std::collections::HashSet::new();
            for e in OpcError::ALL {
                let t = e.text(lang);
                assert!(!t.trim().is_empty(), "{e:?} has no {lang:?} text");
                assert!(seen.insert(t), "{e:?} repeats the {lang:?} text {t:?}");
            }
        }
        for e in OpcError::ALL {
            assert_ne!(
                e.text(Lang::English),
                e.text(Lang::Polish),
                "{e:?} is not translated"
            );
        }
    }

    #[test]
    fn texts_follow_the_opc_foundation_wording() {
        assert_eq!(
            OpcError::InvalidHandle.text(Lang::English),
            "The value of the handle is invalid."
        );
        assert_eq!(
            OpcError::InvalidHandle.text(Lang::Polish),
            "Wartość uchwytu jest nieprawidłowa."
        );
        assert_eq!(OpcError::BadVarType.hresult() as u32, 0x80020008);
        assert_eq!(OpcError::BadVarType.symbol(), "DISP_E_BADVARTYPE");
    }

    #[test]
    fn polish_texts_use_diacritics() {
        // Guards against an accidental ASCII-only (diacritic-stripped) translation.
        let with_diacritics = OpcError::ALL
            .iter()
            .filter(|e| {
                e.text(Lang::Polish)
                    .chars()
                    .any(|c| "ąćęłńóśźżĄĆĘŁŃÓŚŹŻ".contains(c))
            })
            .count();
        assert!(
            with_diacritics * 2 > OpcError::ALL.len(),
            "{with_diacritics}"
        );
    }
}
