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
