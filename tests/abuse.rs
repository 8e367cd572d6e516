//! The server against hostile or broken clients: idle and slow
//! connections, wrong Host headers, malformed requests and images, bursts
//! of large uploads, deletions during precomputes, clients that try to
//! mint metric labels, a data directory that is tampered with or
//! shared, and a restart over many textures.

mod common;
mod server_support;

#[path = "abuse/connections.rs"]
mod connections;
#[path = "abuse/consistency.rs"]
mod consistency;
#[path = "abuse/data_dir.rs"]
mod data_dir;
#[path = "abuse/decoding.rs"]
mod decoding;
#[path = "abuse/deletion.rs"]
mod deletion;
#[path = "abuse/errors.rs"]
mod errors;
#[path = "abuse/hosts.rs"]
mod hosts;
#[path = "abuse/labels.rs"]
mod labels;
#[path = "abuse/raw.rs"]
mod raw;
#[path = "abuse/start.rs"]
mod start;
