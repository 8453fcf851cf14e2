//! sfs: shape from sensors. A daemon that turns the stream of an inertial scanning device into
//! 3D curve networks and smooth surfaces.
//!
//! # Layout, in the order the data flows
//!
//! - `device-protocol` (its own crate): bytes ⇄ packets, the wire format version 1.
//! - [`source`]: where bytes come from (serial port, capture file, stdin, the phone page
//!   served over HTTPS: [`source::phone`]), each on its own thread behind one channel of
//!   [`source::SourceEvent`]s; [`ports`]: the serial ports with
//!   their USB identity, probed for this protocol (`sfs ports`).
//! - [`capture`]: lossless capture of live bytes, written before anything decodes them
//!   (rotated with retention for unattended runs, each piece keeping the session's time);
//!   [`clock`]: the session time from the device's stamps (wraps and reboots bridged).
//! - [`link`]: statistics of the decoded link (packets, rejects, gaps, reboots, STATUS), and
//!   what the link does now (connected, silent, lost, reconnecting: [`link::LinkTracker`]).
//! - [`sensor`]: packets → calibrated samples (HELLO scales, calibration, axis mapping).
//! - [`orientation`]: samples → orientations of the frame [T B N] (TRIAD, the phone's
//!   causal filter and its smoother of finished curves, rests from window statistics, the
//!   q-method mean, disturbance tests).
//! - [`keypad`], [`acquisition`], [`scan`]: orientations and key presses → tagged curves
//!   (the state machine; the open curve kept until `E` and finalised; a phone's stands and
//!   its distances from its speed fitted to the accelerometer, [`acquisition::speed`]; a
//!   Morphorider's wheel skids filled, [`acquisition::skid`]; sensor arrays' windows).
//! - `sfs-geometry` (its own crate, `geometry/`, no I/O): tagged curves → filtered frames
//!   (pre-filter, loop-closure test of the tags, regression on SO(3)) → positions of the
//!   network (Poisson) → surface (cycles, tessellation, cotangent Laplacian, biharmonic
//!   propagation, the mean-curvature-guided fit), with the sparse Cholesky they share.
//! - [`pipeline`]: the one place that turns a scan's curves into products (network, surface,
//!   `network.glb` bytes, warnings), with the caches kept between runs.
//! - [`gltf_out`]: all glTF writing and reading (the output contract).
//! - [`live`]: the worker that rebuilds the outputs after every curve (coalescing).
//! - [`host`]: whether a request's `Host` names this server (the view's and the phone page's
//!   defence against DNS rebinding).
//! - [`view`]: the operator's live view, a web page served while the session runs (the
//!   network, surface, curve being scanned, status and warnings, kept current by server-sent
//!   events; for a monitored structure its shape, alarms and sensors), with the Prometheus
//!   [`metrics`] on the same server.
//! - [`report`]: `report.json`, assembled in one place; [`warning`]: the typed warnings
//!   it lists; [`percentiles`]: the distributions it summarises; [`memory`]: resident size;
//!   [`atomic`]: atomic replacement of output files.
//! - [`session`]: one session, prepared, streamed (source → decoder → acquisition → live
//!   worker and monitor) and finished (scan.json, network.glb, report.json).
//! - [`monitor`]: instrumented structures (sensor arrays): layout → shape per epoch →
//!   metrics against a reference → alarms → rolling outputs (metrics.csv, events.log,
//!   latest.glb, gauges on the view's `/metrics`).
//! - [`settings`]: everything a session runs with, resolved once; [`config`]: the
//!   configuration file (`config/*.toml`), one module per section, resolved into settings;
//!   [`cli`]: the raw flags; [`named_file`]: the files they name, read bounded; `main.rs`
//!   the thin binary over them; [`logging`]: the log lines (human or JSON with the session,
//!   journald-aware).
//! - [`shutdown`]: the stop signal passed into every long-running part; [`service`]: systemd's
//!   readiness, status and watchdog (`deploy/sfs@.service`).
//! - Tools beside the daemon: [`calibrate`] (`sfs calibrate`: ellipsoid and static-pose
//!   fits), [`simulate`] (captures of known shapes: the built-in scenes and the meshes the
//!   project makes, operator timeline, device models), [`eval`] (`sfs eval`: scoring
//!   against a truth).
//!
//! The modules import one another without cycles (checked by `tests/layering.rs`).

pub mod acquisition;
pub mod atomic;
pub mod calibrate;
pub mod capture;
pub mod cli;
pub mod clock;
pub mod config;
pub mod eval;
pub mod gltf_out;
pub mod host;
pub mod keypad;
pub mod link;
pub mod live;
pub mod logging;
pub mod memory;
pub mod metrics;
pub mod monitor;
pub mod named_file;
pub mod orientation;
pub mod percentiles;
pub mod pipeline;
pub mod ports;
pub mod report;
pub mod scan;
pub mod sensor;
pub mod service;
pub mod session;
pub mod settings;
pub mod shutdown;
pub mod simulate;
pub mod source;
pub mod view;
pub mod warning;

/// Exit codes of the `sfs` binary (a stated policy, also in the README).
pub mod exit {
    /// Success.
    pub const OK: i32 = 0;
    /// An unexpected internal error.
    pub const INTERNAL: i32 = 1;
    /// Wrong usage or an invalid configuration file.
    pub const USAGE: i32 = 2;
    /// The input (capture file, serial port, standard input) cannot be opened or read.
    pub const INPUT: i32 = 3;
    /// An output (session directory, capture, report) cannot be written.
    pub const OUTPUT: i32 = 4;
    /// The input was read but cannot give the result asked for (e.g. no calibration fit).
    pub const UNUSABLE: i32 = 5;
    /// A second interrupt signal: exit at once (files are left consistent, not finished).
    pub const INTERRUPTED: i32 = 130;
}
