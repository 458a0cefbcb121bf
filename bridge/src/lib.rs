//! navsync's services on a Zenoh network (<https://zenoh.io>), for the other computers of a
//! vehicle and a ground station: the bridge between a host's iceoryx2 services and Zenoh
//! ([`bridge`]), the wire format ([`wire`]) and the clients for hosts without a local navsync
//! ([`remote`]). Samples keep their time stamps as the source host made them (host-monotonic
//! of that host, and GNSS/UTC): a remote subscriber uses the UTC fields.

#![forbid(unsafe_code)]

pub mod bridge;
pub mod remote;
pub mod wire;

pub use bridge::{BridgeError, BridgeSettings, Mode, RateLimit, SessionSettings};
