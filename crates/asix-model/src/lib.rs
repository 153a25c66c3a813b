//! asix semantics: `ASIXConnect.ini` channels and options, the variable database
//! (attribute table + variable-set tree), item identifiers, derived values, quality
//! rules and the [`Namespace`](ctopc_core::namespace::Namespace) implementation, over the
//! OPC DA model of `ctopc-core`.
//!
//! Everything here is pure; the only file access is in the thin `load_*` wrappers
//! ([`load_config_file`], [`load_database_file`], [`AsixNamespace::load`],
//! [`startup::load_file`]) around the `parse_*` functions that hold the logic.
//! [`startup`] assembles what a server starts with, the embedded demo included.
//!
//! User documentation: `asixconnect.ini.example` (configuration) and
//! `docs/variable-database.md` (database format) at the repository root.
#![forbid(unsafe_code)]

pub mod address_space;
pub mod config;
pub mod format;
pub mod ini;
pub mod itemid;
pub mod namespace;
pub mod quality_rules;
pub mod startup;
pub mod synthetic;
pub mod text;
pub mod vardb;

pub use config::{
    load_config_file, parse_config, AsixConfig, ChannelOptions, ConfigError, ConfigErrorKind,
    DefaultLanguage, LogLevel, Secret, ServerOptions, ServerSelection, UaOptions, BASIC_CHANNEL,
    UA_OPTIONS,
};
pub use format::FormatSpec;
pub use itemid::{parse_item_id, AsmenType, DescriptiveId, ItemId, ItemKey, Suffix, VarItem};
pub use namespace::{
    AsixNamespace, BrowseNode, ChannelDatabase, Derivation, LimitProps, LiveItem,
    PropertyAttributes,
};
pub use quality_rules::{
    apply_quality_rules, apply_quality_rules_with, check_write_value, RuleDef, RuleOptions,
};
pub use startup::{embedded_demo, Loaded};
pub use text::Warning;
pub use vardb::{load_database_file, DbError, Limit, VarDatabase, Variable};
