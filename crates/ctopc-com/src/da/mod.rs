//! The DA floor: the OPC DA objects over the plumbing (`crate::com`) and the portable
//! runtime. The server object (`server`), the group object (`group`), what every object of
//! one server shares (`context`), how the runtime's callbacks reach the clients
//! (`callbacks`), and what each switch of ServerCTOPC.exe does (`host`).

pub mod callbacks;
pub mod context;
pub mod group;
pub mod host;
pub mod server;
