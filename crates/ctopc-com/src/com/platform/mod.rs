//! The platform's quirks, one file per platform, entered only from the apartment guard
//! (`super::apartment`): nothing else in the product asks which platform it runs on.

pub mod wine;
