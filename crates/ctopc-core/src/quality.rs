//! OPC quality: 16 bits `QQSSSSLL` in the low byte, vendor bits 8-15 (asix: 0x0800 Second Limit).

/// A 16-bit OPC DA quality word.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct Quality(pub u16);

impl Quality {
    // Major quality (bits 6-7).
    pub const BAD: Quality = Quality(0x00);
    pub const UNCERTAIN: Quality = Quality(0x40);
    pub const GOOD: Quality = Quality(0xC0);

    // Bad substatus.
    pub const BAD_CONFIG_ERROR: Quality = Quality(0x04);
    pub const BAD_NOT_CONNECTED: Quality = Quality(0x08);
    pub const BAD_DEVICE_FAILURE: Quality = Quality(0x0C);
    pub const BAD_SENSOR_FAILURE: Quality = Quality(0x10);
    pub const BAD_LAST_KNOWN_VALUE: Quality = Quality(0x14);
    pub const BAD_COMM_FAILURE: Quality = Quality(0x18);
    pub const BAD_OUT_OF_SERVICE: Quality = Quality(0x1C);
    pub const BAD_WAITING_FOR_INITIAL_DATA: Quality = Quality(0x20);

    // Uncertain substatus.
    pub const UNCERTAIN_LAST_USABLE: Quality = Quality(0x44);
    pub const UNCERTAIN_SENSOR_NOT_ACCURATE: Quality = Quality(0x50);
    pub const UNCERTAIN_EU_EXCEEDED: Quality = Quality(0x54);
    pub const UNCERTAIN_SUB_NORMAL: Quality = Quality(0x58);

    // Good substatus.
    pub const GOOD_LOCAL_OVERRIDE: Quality = Quality(0xD8);

    // Limit field (bits 0-1).
    pub const LIMIT_MASK: u16 = 0x0003;
    pub const LIMIT_OK: u16 = 0x0000;
    pub const LIMIT_LOW: u16 = 0x0001;
    pub const LIMIT_HIGH: u16 = 0x0002;
    pub const LIMIT_CONST: u16 = 0x0003;

    pub const QUALITY_MASK: u16 = 0x00C0;
    pub const STATUS_MASK: u16 = 0x00FC;
    /// asix vendor bit: an alarm (second) limit was crossed (with CheckLimits).
    pub const VENDOR_SECOND_LIMIT: u16 = 0x0800;

    pub const fn bits(self) -> u16 {
        self.0
    }
    pub const fn is_good(self) -> bool {
        self.0 & Self::QUALITY_MASK == 0xC0
    }
    pub const fn is_uncertain(self) -> bool {
        self.0 & Self::QUALITY_MASK == 0x40
    }
    pub const fn is_bad(self) -> bool {
        self.0 & Self::QUALITY_MASK == 0x00
    }
    /// Quality plus substatus (bits 2-7).
    pub const fn status(self) -> u16 {
        self.0 & Self::STATUS_MASK
    }
    pub const fn limit(self) -> u16 {
        self.0 & Self::LIMIT_MASK
    }
    pub const fn with_limit(self, limit: u16) -> Quality {
        Quality((self.0 & !Self::LIMIT_MASK) | (limit & Self::LIMIT_MASK))
    }
    pub const fn with_vendor(self, bits: u16) -> Quality {
        Quality(self.0 | (bits & 0xFF00))
    }
}

impl Quality {
    /// The OPC name of the major quality ("GOOD", "UNCERTAIN", "BAD"; "N/A" for the
    /// reserved value 0x80).
    pub const fn major_name(self) -> &'static str {
        match self.0 & Self::QUALITY_MASK {
            0xC0 => "GOOD",
            0x40 => "UNCERTAIN",
            0x00 => "BAD",
            _ => "N/A",
        }
    }

    /// The OPC name of the substatus, `None` for the non-specific substatus 0 and for
    /// substatus values the specification does not define.
    pub const fn substatus_name(self) -> Option<&'static str> {
        match self.status() {
            0x04 => Some("Config Error"),
            0x08 => Some("Not Connected"),
            0x0C => Some("Device Failure"),
            0x10 => Some("Sensor Failure"),
            0x14 => Some("Last Known Value"),
            0x18 => Some("Comm Failure"),
            0x1C => Some("Out of Service"),
            0x20 => Some("Waiting for Initial Data"),
            0x44 => Some("Last Usable Value"),
            0x50 => Some("Sensor Not Accurate"),
            0x54 => Some("EU Units Exceeded"),
            0x58 => Some("Sub-Normal"),
            0xD8 => Some("Local Override"),
            _ => None,
        }
    }

    /// The OPC name of the limit field, `None` for "not limited".
    pub const fn limit_name(self) -> Option<&'static str> {
        match self.limit() {
            Self::LIMIT_LOW => Some("Low limit"),
            Self::LIMIT_HIGH => Some("High limit"),
            Self::LIMIT_CONST => Some("Constant"),
            _ => None,
        }
    }
}

/// `MAJOR [Substatus] [[Limit]] [+SecondLimit] [+Vendor(0xNN)]`, e.g. "GOOD",
/// "BAD Comm Failure [Low limit] +SecondLimit". An undefined substatus shows as
/// "Substatus N"; vendor bits other than Second Limit as their hex value.
impl std::fmt::Display for Quality {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.major_name())?;
        let sub = (self.0 & 0x3C) >> 2;
        match self.substatus_name() {
            Some(name) => write!(f, " {name}")?,
            None if sub != 0 => write!(f, " Substatus {sub}")?,
            None => {}
        }
        if let Some(limit) = self.limit_name() {
            write!(f, " [{limit}]")?;
        }
        if self.0 & Self::VENDOR_SECOND_LIMIT != 0 {
            f.write_str(" +SecondLimit")?;
        }
        let other_vendor = self.0 & 0xFF00 & !Self::VENDOR_SECOND_LIMIT;
        if other_vendor != 0 {
            write!(f, " +Vendor(0x{:02X})", other_vendor >> 8)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn display_names_major_substatus_limit_and_vendor_bits() {
        let table: &[(u16, &str)] = &[
            (0xC0, "GOOD"),
            (0xD8, "GOOD Local Override"),
            (0xC3, "GOOD [Constant]"),
            (0x40, "UNCERTAIN"),
            (0x44, "UNCERTAIN Last Usable Value"),
            (0x50, "UNCERTAIN Sensor Not Accurate"),
            (0x54, "UNCERTAIN EU Units Exceeded"),
            (0x56, "UNCERTAIN EU Units Exceeded [High limit]"),
            (0x58, "UNCERTAIN Sub-Normal"),
            (0x00, "BAD"),
            (0x04, "BAD Config Error"),
            (0x08, "BAD Not Connected"),
            (0x0C, "BAD Device Failure"),
            (0x10, "BAD Sensor Failure"),
            (0x14, "BAD Last Known Value"),
            (0x18, "BAD Comm Failure"),
            (0x1C, "BAD Out of Service"),
            (0x20, "BAD Waiting for Initial Data"),
            (0x0819, "BAD Comm Failure [Low limit] +SecondLimit"),
            (0x08C2, "GOOD [High limit] +SecondLimit"),
            (0x24, "BAD Substatus 9"),
            (0x80, "N/A"),
            (0x12C0, "GOOD +Vendor(0x12)"),
            (0x1AC1, "GOOD [Low limit] +SecondLimit +Vendor(0x12)"),
        ];
        for &(bits, text) in table {
            assert_eq!(Quality(bits).to_string(), text, "0x{bits:04X}");
        }
    }

    #[test]
    fn constants_decompose_into_major_substatus_and_limit() {
        let q = Quality::BAD_COMM_FAILURE
            .with_limit(Quality::LIMIT_LOW)
            .with_vendor(Quality::VENDOR_SECOND_LIMIT);
        assert_eq!(q.bits(), 0x0819);
        assert!(q.is_bad() && !q.is_good() && !q.is_uncertain());
        assert_eq!(q.status(), 0x18);
        assert_eq!(q.limit(), Quality::LIMIT_LOW);
        assert!(Quality::GOOD_LOCAL_OVERRIDE.is_good());
        assert!(Quality::UNCERTAIN_SUB_NORMAL.is_uncertain());
        assert_eq!(
            Quality::GOOD
                .with_limit(Quality::LIMIT_CONST)
                .with_limit(Quality::LIMIT_OK),
            Quality::GOOD
        );
    }
}
