//! The resolved settings of a session: everything it runs with, checked and with its
//! defaults, resolved once (from a configuration file by the `config` module, or the
//! defaults alone) and handed down. Derived rules live here, next to what they derive.

use crate::acquisition::AcquisitionConfig;
use crate::capture::Rotation;
use crate::monitor::settings::MonitorConfig;
use crate::source::SourceSpec;
use sfs_geometry::network::NetworkParams;
use sfs_geometry::surface::fit::SurfaceParams;
use std::time::Duration;

/// Default serial speed (the wire format's default; a phone's Bluetooth serial ignores it).
pub const DEFAULT_BAUD: u32 = 115_200;
/// Default serial silence watchdog.
pub const DEFAULT_WATCHDOG_MS: u64 = 3_000;

/// What a session does with the packets, and where they come from when configured.
#[derive(Debug, Clone)]
pub struct Settings {
    /// The configured source (`[source]`); `None` without a configuration file (the command
    /// line names one).
    pub source: Option<SourceSpec>,
    /// The serial link's speed and silence watchdog (`[source]`), also for `--serial`.
    pub serial: SerialSettings,
    pub acquisition: AcquisitionConfig,
    pub network: NetworkParams,
    /// Nodes joined after the fact (`[network] join_*`, `refuse`; issue 34).
    pub joins: sfs_geometry::network::join::JoinSettings,
    /// Surfacing settings; `None` writes the network only.
    pub surface: Option<SurfaceParams>,
    /// Reconstruct after every finished curve (the live worker), not only at the end.
    pub live: bool,
    /// Keep a copy of `network.glb` per curve (`snapshots/curve-NNN.glb`), live updates only.
    pub snapshots: bool,
    /// Monitoring of an instrumented structure (set with [`Settings::with_monitor`]).
    pub monitor: Option<MonitorConfig>,
    /// Rotation of a live session's capture; `None`: one file.
    pub capture_rotation: Option<Rotation>,
    /// Where the live view is served (`[view] address`, `--view`); `None`: no view.
    pub view: Option<std::net::SocketAddr>,
    /// Keep serving the view (and the metrics) after the session ends, until interrupted
    /// (`sfs replay --view`, so a recorded session can be looked at).
    pub keep_serving: bool,
    /// Who the view answers besides this machine's addresses and `localhost`
    /// ([`crate::view::access`]).
    pub view_access: ViewAccess,
    /// `[phone]`: where the phone page is served and its certificate kept (`sfs run --phone`
    /// and a configuration with `[phone]` and no `[source]` read the phone).
    pub phone: Option<crate::source::phone::PhoneSpec>,
}

/// `[view] allowed_hosts` and `[view] token`.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ViewAccess {
    pub allowed_hosts: Vec<String>,
    pub token: Option<String>,
}

/// A serial link's settings.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SerialSettings {
    pub baud: u32,
    pub watchdog: Duration,
}

impl Default for SerialSettings {
    fn default() -> Self {
        SerialSettings {
            baud: DEFAULT_BAUD,
            watchdog: Duration::from_millis(DEFAULT_WATCHDOG_MS),
        }
    }
}

impl Default for Settings {
    /// Documented defaults; the surface is made, with soft constraints
    /// ([`crate::pipeline::SCAN_SOFTNESS`]) and live updates that keep the faces they can
    /// ([`crate::pipeline::LIVE_REUSE_TOLERANCE`]) and regress the new curve's neighbourhood
    /// ([`crate::pipeline::LIVE_LOCAL_WINDOW`]).
    fn default() -> Self {
        Settings {
            source: None,
            serial: SerialSettings::default(),
            acquisition: AcquisitionConfig::default(),
            network: NetworkParams {
                local_window: crate::pipeline::LIVE_LOCAL_WINDOW,
                ..Default::default()
            },
            joins: Default::default(),
            surface: Some(SurfaceParams {
                soft: crate::pipeline::SCAN_SOFTNESS,
                reuse_tolerance: crate::pipeline::LIVE_REUSE_TOLERANCE,
                ..Default::default()
            }),
            live: true,
            snapshots: false,
            monitor: None,
            capture_rotation: None,
            view: None,
            keep_serving: false,
            view_access: ViewAccess::default(),
            phone: None,
        }
    }
}

impl Settings {
    /// Monitoring with `m`: acquisition averages each sensor's orientation over one window
    /// per epoch (`array_window = 1 / epoch_hz`).
    pub fn with_monitor(mut self, m: MonitorConfig) -> Settings {
        self.acquisition.array_window = 1.0 / m.epoch_hz;
        self.monitor = Some(m);
        self
    }
}
