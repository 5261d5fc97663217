//! Criterion benchmarks for skymesh; this library is empty on purpose.
//!
//! `benches/codecs.rs` times decode and encode per message of every protocol codec
//! (solo-proto, gc-proto, imc-proto, dji-proto, digiview-proto, and the MAVLink 2
//! framing of autopilot-link and the `mavlink` crate); `benches/arbiter.rs` times
//! the command arbiter's decision. Run `cargo bench -p skymesh-benches`.
//!
//! The package is a workspace member of its own so that criterion is compiled only
//! by `cargo bench`, never by `cargo test --workspace`.
