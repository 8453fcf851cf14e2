//! Raw command-line flags (clap). Resolution into a [`crate::source::SourceSpec`] and session
//! settings happens in `main`, on top of the configuration file. Every enumerated flag is a
//! typed value: a bad one is a usage error (exit 2) naming the values allowed.

use crate::simulate::structure::StructureKind;
use crate::simulate::Profile;
use crate::source::Pace;
use clap::builder::PossibleValue;
use clap::{Args, Parser, Subcommand, ValueEnum};
use device_protocol::DeviceKind;
use std::path::PathBuf;

/// A device kind on the command line, by its name ([`DeviceKind::name`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Device(pub DeviceKind);

impl ValueEnum for Device {
    fn value_variants<'a>() -> &'a [Self] {
        &[
            Device(DeviceKind::Morphorider),
            Device(DeviceKind::Phone),
            Device(DeviceKind::SensorArray),
        ]
    }

    fn to_possible_value(&self) -> Option<PossibleValue> {
        Some(PossibleValue::new(self.0.name()))
    }
}

/// Shape from sensors: turns the stream of an inertial scanning device into 3D curve networks.
#[derive(Debug, Parser)]
#[command(name = "sfs", version, about, long_about = None)]
pub struct Cli {
    /// Log format on standard error.
    #[arg(long, value_enum, default_value_t = LogFormat::Human, global = true)]
    pub log_format: LogFormat,
    /// Log filter (tracing `EnvFilter` syntax); overrides RUST_LOG. Default: info.
    #[arg(long, global = true)]
    pub log: Option<String>,
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum LogFormat {
    Human,
    Json,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Replay a capture file through the pipeline; write DIR/report.json, DIR/scan.json and
    /// DIR/network.glb.
    ///
    /// Writes, once the capture has been read: DIR/report.json (the link statistics, the
    /// curves, the reconstruction's figures, every warning), DIR/scan.json (the tagged
    /// curves: orientations, distances, nodes) and DIR/network.glb (the curve network and
    /// its surface, glTF 2.0); a sensor array's capture, replayed with a `[monitor]`
    /// configuration (--config), writes the monitoring outputs instead (metrics.csv,
    /// events.log, latest.glb, reference.json). The source is the capture file (the raw
    /// bytes a device sent: a session's capture.bin, or sfs simulate's PREFIX.bin); a
    /// configuration's `[source]` is ignored. With --view the outputs are also rebuilt after
    /// every curve and shown in a browser. Exit codes: 0 done, 2 usage or configuration, 3
    /// the capture cannot be read, 4 an output cannot be written, 5 nothing usable in the
    /// capture (no packet).
    #[command(verbatim_doc_comment)]
    Replay(ReplayArgs),
    /// Read a live device, capture every byte to SESSION/capture.bin, and rebuild
    /// SESSION/network.glb and SESSION/report.json after every curve.
    ///
    /// Sources, one of: a serial port (--serial PATH, or `[source]` kind = "serial" in the
    /// configuration), standard input (--stdin, or kind = "stdin"), a phone (--phone, or a
    /// `[phone]` section: the daemon serves the phone page over HTTPS), or a capture file
    /// replayed as if live (kind = "replay" with its path and pace, as config/demo.toml).
    /// Writes into SESSION: capture.bin (every byte, before it is decoded), config.toml (the
    /// configuration it started with, the source and view of the flags written in, so that
    /// --resume SESSION alone continues it), network.glb and report.json (after
    /// every curve the operator ends with E, replaced atomically), scan.json (at the end);
    /// with `[monitor]`, metrics.csv, events.log, latest.glb and reference.json. A session is
    /// stopped with Ctrl-C or SIGTERM (the outputs are finished first) and continued with
    /// --resume SESSION. Exit codes: 0 done, 2 usage or configuration, 3 the source cannot
    /// be opened, 4 an output cannot be written.
    #[command(verbatim_doc_comment)]
    Run(RunArgs),
    /// Fit the magnetometer (hard/soft iron), accelerometer (bias/scale) and gyroscope bias from
    /// a capture of the device turned through many orientations with static rests; prints the
    /// fit quality and a `[calibration]` snippet for the configuration.
    Calibrate(CalibrateArgs),
    /// Simulate a scan of a known scene: writes PREFIX.bin (the exact bytes a device would
    /// send) and PREFIX.truth.json (nodes, curves with normals, surface, bounding-box diagonal).
    Simulate(SimulateArgs),
    /// Score a reconstruction against a simulation's truth (the paper's metric: curve points to
    /// the truth network and surface vertices to the truth surface after a rigid registration,
    /// in % of the bounding-box diagonal). Prints one JSON object.
    Eval(EvalArgs),
    /// Configuration files.
    #[command(subcommand)]
    Config(ConfigCommand),
    /// List the serial ports with their type and USB identity (vendor:product id,
    /// manufacturer, product, serial number); with --probe, open each for a moment and say
    /// which speak this protocol (the HELLO's device kind, id, firmware and rate).
    Ports(PortsArgs),
}

#[derive(Debug, Args)]
pub struct PortsArgs {
    /// Open each port for up to --probe-secs and decode what it sends.
    #[arg(long)]
    pub probe: bool,
    /// How long a probe listens, seconds (a device sends HELLO every 5 s; valid packets before
    /// it are enough to say it speaks the protocol).
    #[arg(long, default_value_t = 2.0, value_parser = probe_secs)]
    pub probe_secs: f64,
    /// Serial speed of the probes, baud.
    #[arg(long, default_value_t = crate::settings::DEFAULT_BAUD)]
    pub baud: u32,
    /// Print JSON (an array of ports) instead of lines.
    #[arg(long)]
    pub json: bool,
    /// More ports to list and probe (a udev symlink such as /dev/sfs-morphorider-…, a
    /// pseudo-terminal).
    pub paths: Vec<PathBuf>,
}

fn probe_secs(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(x) if (0.05..=60.0).contains(&x) => Ok(x),
        Ok(x) => Err(format!("{x} s is not between 0.05 and 60")),
        Err(e) => Err(e.to_string()),
    }
}

#[derive(Debug, Args)]
pub struct EvalArgs {
    /// The truth file written by `sfs simulate`.
    #[arg(long)]
    pub truth: PathBuf,
    /// The reconstruction (`network.glb`).
    #[arg(long)]
    pub glb: PathBuf,
    /// Write the JSON object to this new file instead of standard output (an existing file
    /// is refused unless --force; an input never). `--report` is an old name of it.
    #[arg(long, value_name = "FILE", alias = "report")]
    pub out: Option<PathBuf>,
    /// Replace an existing --out file (never one of the inputs).
    #[arg(long)]
    pub force: bool,
}

#[derive(Debug, Args)]
#[command(group(clap::ArgGroup::new("what").required(true).args(["scene", "structure", "list"])))]
pub struct SimulateArgs {
    /// A built-in scene by NAME (`--list` names them), or a scene file given as PATH.toml.
    #[arg(long, value_name = "NAME|PATH.toml")]
    pub scene: Option<String>,
    /// List the built-in scenes with their descriptions, and exit.
    #[arg(long)]
    pub list: bool,
    /// A deforming instrumented structure streamed by a sensor array (monitoring mode):
    /// PREFIX.truth.json then holds the layout and the truth at every second.
    #[arg(long, value_enum)]
    pub structure: Option<StructureKind>,
    /// Structures: seconds to simulate.
    #[arg(long, default_value_t = 120.0)]
    pub duration: f64,
    /// The device scanning it.
    #[arg(long, value_enum, default_value = "morphorider")]
    pub device: Device,
    /// Seed of every random choice: the same seed gives the same bytes.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Output prefix: PREFIX.bin and PREFIX.truth.json.
    #[arg(long, required_unless_present = "list")]
    pub out: Option<PathBuf>,
    /// `default` (documented noise, rare link faults) or `field` (what real sessions bring).
    #[arg(long, value_enum, default_value = "default")]
    pub profile: Profile,
    /// Leave this fraction (0 to 1) of the crossings untagged on one of their curves: the
    /// operator rolls through without typing there (chosen with the seed; never a curve's
    /// first or last tag). The truth still names every crossing.
    #[arg(long, value_name = "FRACTION", default_value_t = 0.0)]
    pub untagged: f64,
    /// Plant one operator or field fault: a wrong node typed, a slip over one segment, a
    /// late Enter, a magnet under one stretch of a curve. Placed and sized on a random stream
    /// of its own (the rest of the capture is the same seed's); the truth's `faults` says where.
    #[arg(long, value_enum, value_name = "KIND")]
    pub fault: Option<crate::simulate::planted::Planted>,
}

#[derive(Debug, Args)]
pub struct CalibrateArgs {
    /// The capture file.
    pub capture: PathBuf,
    /// Sensor arrays: the sensor to calibrate.
    #[arg(long, default_value_t = 0)]
    pub sensor: u16,
}

#[derive(Debug, Args)]
pub struct ReplayArgs {
    /// The capture file (raw bytes as the device sent them).
    pub capture: PathBuf,
    /// Output directory (created if missing). One that already holds a session (a
    /// capture.bin) or the outputs of a run or a replay is refused unless --force.
    #[arg(long, short)]
    pub out: PathBuf,
    /// Write into an --out directory that already holds outputs, replacing them.
    #[arg(long)]
    pub force: bool,
    /// Replay as fast as possible ("fast"), paced by the device timestamps ("realtime"), or
    /// paced N times faster ("x10").
    #[arg(long, default_value = "fast", value_parser = |s: &str| s.parse::<Pace>())]
    pub pace: Pace,
    /// Configuration file for calibration and processing settings (its `[source]` is ignored).
    #[arg(long, short)]
    pub config: Option<PathBuf>,
    /// Serve the live view (a web page: the network as it grows, the status, the warnings)
    /// at ADDR (default 127.0.0.1:8040), with live updates after every curve; it keeps
    /// serving after the end of the capture until interrupted.
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = crate::view::DEFAULT_ADDRESS, value_parser = crate::view::parse_address)]
    pub view: Option<std::net::SocketAddr>,
}

#[derive(Debug, Args)]
#[command(group(clap::ArgGroup::new("dir").required(true).args(["session", "resume"])))]
pub struct RunArgs {
    /// Configuration file (TOML). Flags below override it.
    #[arg(long, short)]
    pub config: Option<PathBuf>,
    /// Serial port path (e.g. /dev/ttyUSB0).
    #[arg(long, conflicts_with = "stdin")]
    pub serial: Option<PathBuf>,
    /// Serial speed in baud.
    #[arg(long)]
    pub baud: Option<u32>,
    /// Silence, in milliseconds, after which the serial link counts as lost.
    #[arg(long)]
    pub watchdog_ms: Option<u64>,
    /// Read the device stream from standard input.
    #[arg(long)]
    pub stdin: bool,
    /// Scan with a phone: serve the phone page over HTTPS at ADDR (default `[phone] address`,
    /// else 0.0.0.0:8443, every interface) and read what it streams. A port alone (`--phone
    /// 8443`) means every interface, as a phone is another machine (`--view 8040` alone means
    /// this machine only). Prints the page's address (also as a QR code, and into
    /// SESSION/phone.url) and the certificate's fingerprint; a loopback address is warned about.
    #[arg(long, value_name = "ADDR", num_args = 0..=1, conflicts_with_all = ["stdin", "serial"], value_parser = crate::source::phone::parse_address)]
    pub phone: Option<Option<std::net::SocketAddr>>,
    /// Session directory of a new session (created if missing; refused if it already holds
    /// a capture: continue that one with --resume).
    #[arg(long, short)]
    pub session: Option<PathBuf>,
    /// Continue the session in this directory: its capture.bin is decoded first (the curves so
    /// far are rebuilt), then the device's bytes are appended to it. Without --config, the
    /// configuration the session started with (SESSION/config.toml) is used.
    #[arg(long, value_name = "SESSION")]
    pub resume: Option<PathBuf>,
    /// With --session: when the directory already holds a capture, continue it as --resume
    /// would instead of refusing it (a service restarted after a crash, a stall or a reboot
    /// keeps one session: deploy/sfs@.service).
    #[arg(long = "continue", requires = "session")]
    pub continue_existing: bool,
    /// Serve the live view (a web page: the network as it grows, the curve being scanned,
    /// the status, the warnings) at ADDR (default 127.0.0.1:8040) while the session runs;
    /// overrides `[view] address`. A port alone means this machine only (127.0.0.1:PORT);
    /// another machine needs an address (`0.0.0.0:8040`) and `[view] token`.
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = crate::view::DEFAULT_ADDRESS, value_parser = crate::view::parse_address)]
    pub view: Option<std::net::SocketAddr>,
}

#[derive(Debug, Subcommand)]
pub enum ConfigCommand {
    /// Check a configuration file; every error names the key and the reason.
    Check {
        /// The file to check.
        file: PathBuf,
    },
}
