//! OPC DA item property IDs (IOPCItemProperties, IOPCBrowse::GetProperties), their
//! canonical data types and descriptions in English (the OPC Foundation's wording, as
//! opcda.h of DA 3.0 spells it) and Polish.
//!
//! Sets: 1-8 OPC-specific (1-6 every item has; 7-8 EU type and info), 100-108 related to
//! the value, 200-207 operator displays (DA 2.05a; dropped from DA 3.0's opcda.idl),
//! 300-313 alarms and conditions, 600-609 complex data and DA 3.0 write behaviour.
//! IDs 5000 and above are vendor-specific; ServerCTOPC defines none: the asix warning and
//! alarm limits map onto 307-310 (HiHi/Hi/Lo/LoLo Limit).
//!
//! Which of them an item has, and their values: [`item`] (re-exported here).

use crate::lang::Lang;
use crate::{OpcError, OpcResult, VarType};

pub mod item;

pub use item::{
    available_ids, fill_live, is_live, lookup_item_ids, needs_read, property, property_item_id,
    resolve_item, static_properties, ItemInfo, Prop, PropertyContext, VALUE_MAX_AGE_FACTOR,
};

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
pub const OPC_PROPERTY_DEFAULT_DISPLAY: u32 = 200;
pub const OPC_PROPERTY_FOREGROUND_COLOR: u32 = 201;
pub const OPC_PROPERTY_BACKGROUND_COLOR: u32 = 202;
pub const OPC_PROPERTY_BLINK: u32 = 203;
pub const OPC_PROPERTY_BMP_FILE: u32 = 204;
pub const OPC_PROPERTY_DISPLAY_SOUND_FILE: u32 = 205;
pub const OPC_PROPERTY_HTML_FILE: u32 = 206;
pub const OPC_PROPERTY_AVI_FILE: u32 = 207;
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

/// The first vendor-specific property ID.
pub const OPC_PROPERTY_VENDOR_FIRST: u32 = 5000;

/// The properties every item has (OPC's "fixed" set, also in OPCITEMATTRIBUTES).
pub const FIXED_PROPERTY_IDS: [u32; 6] = [
    OPC_PROPERTY_DATATYPE,
    OPC_PROPERTY_VALUE,
    OPC_PROPERTY_QUALITY,
    OPC_PROPERTY_TIMESTAMP,
    OPC_PROPERTY_ACCESS_RIGHTS,
    OPC_PROPERTY_SCAN_RATE,
];

/// One standard item property.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PropertyInfo {
    pub id: u32,
    /// The VARTYPE of the property value (VT_VARIANT for the item value, whose type is the
    /// item's canonical type).
    pub var_type: VarType,
    /// The OPC Foundation's description (DA 3.0 opcda.h).
    pub description_en: &'static str,
    pub description_pl: &'static str,
    /// Defined in DA 3.0's opcda.idl (false for the DA 2.05a-only 200-207).
    pub da3: bool,
}

impl PropertyInfo {
    pub const fn description(&self, lang: Lang) -> &'static str {
        match lang {
            Lang::English => self.description_en,
            Lang::Polish => self.description_pl,
        }
    }
}

const fn p(id: u32, vt: VarType, en: &'static str, pl: &'static str) -> PropertyInfo {
    PropertyInfo {
        id,
        var_type: vt,
        description_en: en,
        description_pl: pl,
        da3: true,
    }
}

const fn p2(id: u32, vt: VarType, en: &'static str, pl: &'static str) -> PropertyInfo {
    PropertyInfo {
        id,
        var_type: vt,
        description_en: en,
        description_pl: pl,
        da3: false,
    }
}

const BSTR_ARRAY: VarType = VarType::array_of(VarType::BSTR);

/// Every standard property, in ascending ID order.
pub static PROPERTIES: &[PropertyInfo] = &[
    p(
        1,
        VarType::I2,
        "Item Canonical Data Type",
        "Kanoniczny typ danych elementu",
    ),
    p(2, VarType::VARIANT, "Item Value", "Wartość elementu"),
    p(3, VarType::I2, "Item Quality", "Jakość elementu"),
    p(
        4,
        VarType::DATE,
        "Item Timestamp",
        "Znacznik czasu elementu",
    ),
    p(
        5,
        VarType::I4,
        "Item Access Rights",
        "Prawa dostępu do elementu",
    ),
    p(
        6,
        VarType::R4,
        "Server Scan Rate",
        "Częstotliwość odczytu serwera",
    ),
    p(
        7,
        VarType::I4,
        "Item EU Type",
        "Typ jednostek inżynierskich elementu",
    ),
    p(
        8,
        BSTR_ARRAY,
        "Item EU Info",
        "Informacje o jednostkach inżynierskich elementu",
    ),
    p(100, VarType::BSTR, "EU Units", "Jednostka"),
    p(101, VarType::BSTR, "Item Description", "Opis elementu"),
    p(102, VarType::R8, "High EU", "Górna granica zakresu"),
    p(103, VarType::R8, "Low EU", "Dolna granica zakresu"),
    p(
        104,
        VarType::R8,
        "High Instrument Range",
        "Górna granica zakresu przyrządu",
    ),
    p(
        105,
        VarType::R8,
        "Low Instrument Range",
        "Dolna granica zakresu przyrządu",
    ),
    p(
        106,
        VarType::BSTR,
        "Contact Close Label",
        "Opis stanu zamkniętego styku",
    ),
    p(
        107,
        VarType::BSTR,
        "Contact Open Label",
        "Opis stanu otwartego styku",
    ),
    p(108, VarType::I4, "Item Timezone", "Strefa czasowa elementu"),
    p2(200, VarType::BSTR, "Default Display", "Domyślny ekran"),
    p2(
        201,
        VarType::I4,
        "Current Foreground Color",
        "Bieżący kolor pierwszego planu",
    ),
    p2(
        202,
        VarType::I4,
        "Current Background Color",
        "Bieżący kolor tła",
    ),
    p2(203, VarType::BOOL, "Current Blink", "Bieżące miganie"),
    p2(204, VarType::BSTR, "BMP File", "Plik BMP"),
    p2(205, VarType::BSTR, "Sound File", "Plik dźwiękowy"),
    p2(206, VarType::BSTR, "HTML File", "Plik HTML"),
    p2(207, VarType::BSTR, "AVI File", "Plik AVI"),
    p(300, VarType::BSTR, "Condition Status", "Stan warunku"),
    p(
        301,
        VarType::BSTR,
        "Alarm Quick Help",
        "Krótka pomoc do alarmu",
    ),
    p(
        302,
        BSTR_ARRAY,
        "Alarm Area List",
        "Lista obszarów alarmowych",
    ),
    p(
        303,
        VarType::BSTR,
        "Primary Alarm Area",
        "Główny obszar alarmowy",
    ),
    p(304, VarType::BSTR, "Condition Logic", "Logika warunku"),
    p(305, VarType::BSTR, "Limit Exceeded", "Przekroczona granica"),
    p(306, VarType::R8, "Deadband", "Strefa nieczułości"),
    p(307, VarType::R8, "HiHi Limit", "Górna granica alarmowa"),
    p(308, VarType::R8, "Hi Limit", "Górna granica ostrzegawcza"),
    p(309, VarType::R8, "Lo Limit", "Dolna granica ostrzegawcza"),
    p(310, VarType::R8, "LoLo Limit", "Dolna granica alarmowa"),
    p(
        311,
        VarType::R8,
        "Rate of Change Limit",
        "Granica szybkości zmian",
    ),
    p(312, VarType::R8, "Deviation Limit", "Granica odchyłki"),
    p(313, VarType::BSTR, "Sound File", "Plik dźwiękowy alarmu"),
    p(
        600,
        VarType::BSTR,
        "Type System ID",
        "Identyfikator systemu typów",
    ),
    p(
        601,
        VarType::BSTR,
        "Dictionary ID",
        "Identyfikator słownika",
    ),
    p(602, VarType::BSTR, "Type ID", "Identyfikator typu"),
    p(603, VarType::VARIANT, "Dictionary", "Słownik"),
    p(604, VarType::VARIANT, "Type Description", "Opis typu"),
    p(605, VarType::BSTR, "Consistency Window", "Okno spójności"),
    p(606, VarType::BSTR, "Write Behavior", "Sposób zapisu"),
    p(
        607,
        VarType::BSTR,
        "Unconverted Item ID",
        "Identyfikator elementu bez konwersji",
    ),
    p(
        608,
        VarType::BSTR,
        "Unfiltered Item ID",
        "Identyfikator elementu bez filtru",
    ),
    p(
        609,
        VarType::BSTR,
        "Data Filter Value",
        "Wartość filtru danych",
    ),
];

/// The standard property with this ID.
pub fn property_info(id: u32) -> Option<&'static PropertyInfo> {
    PROPERTIES
        .binary_search_by_key(&id, |p| p.id)
        .ok()
        .map(|i| &PROPERTIES[i])
}

/// True for an OPC-defined property ID (DA 2.05a or 3.0).
pub fn is_valid_property_id(id: u32) -> bool {
    property_info(id).is_some()
}

/// True for the vendor-specific range (5000 and above).
pub const fn is_vendor_property_id(id: u32) -> bool {
    id >= OPC_PROPERTY_VENDOR_FIRST
}

/// The standard property, or OPC_E_INVALID_PID (the per-property error of
/// GetItemProperties / LookupItemIDs / IOPCBrowse::GetProperties).
pub fn require_property(id: u32) -> OpcResult<&'static PropertyInfo> {
    property_info(id).ok_or(OpcError::InvalidPid)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_is_sorted_unique_and_fully_described() {
        for w in PROPERTIES.windows(2) {
            assert!(w[0].id < w[1].id, "{} before {}", w[0].id, w[1].id);
        }
        for lang in Lang::ALL {
            let mut seen = std::collections::HashSet::new();
            for p in PROPERTIES {
                let d = p.description(lang);
                assert!(!d.is_empty(), "{} has no {lang:?} description", p.id);
                // 205 and 313 are both "Sound File" in the OPC specifications.
                if p.id != 313 {
                    assert!(seen.insert(d), "{} repeats {d:?}", p.id);
                }
            }
        }
    }

    #[test]
    fn ids_have_the_canonical_types_of_the_specification() {
        let table: &[(u32, VarType, &str)] = &[
            (1, VarType::I2, "Item Canonical Data Type"),
            (2, VarType::VARIANT, "Item Value"),
            (3, VarType::I2, "Item Quality"),
            (4, VarType::DATE, "Item Timestamp"),
            (5, VarType::I4, "Item Access Rights"),
            (6, VarType::R4, "Server Scan Rate"),
            (7, VarType::I4, "Item EU Type"),
            (8, VarType(0x2008), "Item EU Info"),
            (100, VarType::BSTR, "EU Units"),
            (101, VarType::BSTR, "Item Description"),
            (102, VarType::R8, "High EU"),
            (103, VarType::R8, "Low EU"),
            (108, VarType::I4, "Item Timezone"),
            (203, VarType::BOOL, "Current Blink"),
            (302, VarType(0x2008), "Alarm Area List"),
            (307, VarType::R8, "HiHi Limit"),
            (310, VarType::R8, "LoLo Limit"),
            (606, VarType::BSTR, "Write Behavior"),
            (609, VarType::BSTR, "Data Filter Value"),
        ];
        for &(id, vt, en) in table {
            let p = property_info(id).unwrap();
            assert_eq!((p.var_type, p.description_en), (vt, en), "property {id}");
        }
        assert_eq!(
            property_info(101).unwrap().description(Lang::Polish),
            "Opis elementu"
        );
    }

    #[test]
    fn unknown_ids_are_invalid_pid() {
        for id in [
            0,
            9,
            99,
            109,
            199,
            208,
            299,
            314,
            599,
            610,
            4999,
            5000,
            u32::MAX,
        ] {
            assert!(!is_valid_property_id(id), "{id}");
            assert_eq!(require_property(id), Err(OpcError::InvalidPid));
        }
        for id in FIXED_PROPERTY_IDS {
            assert_eq!(require_property(id).map(|p| p.id), Ok(id));
        }
        assert!(is_vendor_property_id(5000) && !is_vendor_property_id(4999));
    }

    #[test]
    fn only_the_display_range_is_missing_from_da3() {
        for p in PROPERTIES {
            assert_eq!(p.da3, !(200..=207).contains(&p.id), "{}", p.id);
        }
    }
}
