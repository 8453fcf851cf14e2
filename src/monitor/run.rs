//! The monitoring loop of a session: sensor-array epochs (per-sensor orientations averaged by
//! acquisition over windows of `1 / epoch_hz`) grouped by window → the shape
//! ([`super::epoch`]) → the reference (mean of the first `reference_s` seconds, or
//! `reference_file`) → metrics and alarms → outputs in the session directory:
//!
//! - `reference.json`: the reference built from the first seconds, once complete
//!   ([`super::metrics::ReferenceFile`]; name it in `reference_file` to keep it across runs);
//! - `metrics.csv`: one line per epoch (time, displacement, curvature change, the layout's
//!   sensors left out: missing, saturated, magnetically disturbed, each counted once and
//!   interpolated across; alarms raised as `metric>threshold` separated by `;`), rotated to
//!   `metrics.1.csv`, … when it passes `metrics_max_mb`, keeping `metrics_keep` files;
//! - `events.log`: one line per alarm raised or cleared, and per sensor of the layout left
//!   out (missing, saturated, disturbed) or back (`ok`), when that changes (also in the
//!   log); rotated as `metrics.csv` is;
//! - `latest.glb`: the network of the latest shape (and its surface with `surface = true`),
//!   replaced atomically every `latest_every` epochs.

use super::alarm::{Alarm, Transition};
use super::epoch::{EpochParams, EpochReconstructor};
use super::metrics::{compare, Metrics, ReferenceBuilder, Shape};
use super::settings::MonitorConfig;
use crate::atomic::remove_if_present;
use crate::orientation::flags;
use crate::scan::ArrayEpoch;
use nalgebra::{Quaternion, UnitQuaternion};
use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Name of the metrics time series in a session directory.
pub const METRICS_FILE: &str = "metrics.csv";
/// Name of the alarm events file.
pub const EVENTS_FILE: &str = "events.log";
/// Name of the latest shape.
pub const LATEST_FILE: &str = "latest.glb";
/// Name of the reference a session built.
pub const REFERENCE_FILE: &str = "reference.json";

const CSV_HEADER: &str = "t_s,max_displacement_m,mean_displacement_m,max_curvature_change_rad_m,missing,saturated,disturbed,alarms\n";

/// `dir/NAME.EXT` → `NAME.1.EXT` → … → `NAME.KEEP.EXT` (the oldest beyond is deleted).
fn rotate_file(dir: &Path, file: &str, keep: usize) -> std::io::Result<()> {
    let (stem, ext) = file.rsplit_once('.').unwrap_or((file, ""));
    crate::atomic::shift_generations(
        |k| match k {
            0 => dir.join(file),
            k => dir.join(format!("{stem}.{k}.{ext}")),
        },
        keep,
    )
}

/// The time and the alarms raised of the last complete line of a metrics file (a line cut by
/// a kill is removed), `None` without one.
fn last_metrics_line(path: &Path) -> std::io::Result<Option<(f64, Vec<String>)>> {
    use std::io::{Read, Seek, SeekFrom};
    let mut f = match std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(path)
    {
        Ok(f) => f,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(e),
    };
    let len = f.metadata()?.len();
    let from = len.saturating_sub(4096);
    f.seek(SeekFrom::Start(from))?;
    let mut tail = Vec::new();
    f.read_to_end(&mut tail)?;
    let Some(end) = tail.iter().rposition(|&b| b == b'\n') else {
        return Ok(None);
    };
    if end + 1 < tail.len() {
        tracing::warn!(
            "monitor: {}: its last line was cut ({} bytes); removed",
            path.display(),
            tail.len() - end - 1
        );
        f.set_len(from + end as u64 + 1)?;
    }
    let body = &tail[..end];
    let line = match body.iter().rposition(|&b| b == b'\n') {
        Some(k) => &body[k + 1..],
        None => body,
    };
    let Ok(line) = std::str::from_utf8(line) else {
        return Ok(None);
    };
    let fields: Vec<&str> = line.split(',').collect();
    let Ok(t) = fields[0].parse::<f64>() else {
        return Ok(None);
    };
    let alarms = fields
        .get(7)
        .map(|a| {
            a.split(';')
                .filter(|x| !x.is_empty())
                .map(String::from)
                .collect()
        })
        .unwrap_or_default();
    Ok(Some((t, alarms)))
}

/// What a monitoring session did, for `report.json`.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct MonitorReport {
    pub epochs: u64,
    /// Epochs that could not be reconstructed (no curve with a sensor), each also a warning.
    pub failed: u64,
    /// Sensor epochs that came after their window had closed (out of time order), ignored.
    pub late: u64,
    /// Sensors streaming that the layout does not place (ignored; each also a warning, once):
    /// a layout numbered otherwise than the array, or a sensor left out of it.
    pub unknown_sensors: Vec<u16>,
    /// Epochs averaged into the reference (0: the reference came from a file).
    pub reference_epochs: usize,
    pub alarms_raised: u64,
    pub last: Option<Metrics>,
    /// Resident memory at the first epoch past one hour of session time, and at the end, MB
    /// (memory must stay flat in unattended operation).
    pub rss_mb_after_first_hour: Option<f64>,
    pub rss_mb: Option<f64>,
    /// Surfaces made for `latest.glb`, the shapes that could not be surfaced (each also a
    /// warning), and the time of the last, ms.
    pub surfaces: u64,
    pub surfaces_failed: u64,
    pub surface_ms: Option<f64>,
    /// Numeric factorisations the surfaces took (issue 19: the structure's faces are kept from
    /// the first surface and their weights from the second, so two in all; every later
    /// surface is back-substitutions).
    pub surface_factorisations: usize,
}

/// What the live view shows of a monitoring session (`/status` `monitor`).
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct MonitorStatus {
    /// Session time of the latest epoch, s.
    pub epoch_t_s: Option<f64>,
    pub epochs: u64,
    pub failed: u64,
    /// Why epochs fail, while they do.
    pub failing: Option<String>,
    /// Epochs in the reference so far, of how many (`ready` once complete or from a file).
    pub reference_epochs: usize,
    pub reference_of: usize,
    pub reference_ready: bool,
    /// The latest epoch's metrics against the reference.
    pub last: Option<Metrics>,
    pub alarms: Vec<AlarmStatus>,
    /// Every sensor of the layout: `ok`, or why it is left out (missing, saturated,
    /// disturbed).
    pub sensors: Vec<SensorStatus>,
    /// Sensors streaming that the layout does not place.
    pub unknown_sensors: Vec<u16>,
}

#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct AlarmStatus {
    pub metric: &'static str,
    pub threshold: f64,
    pub raised: bool,
}

#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SensorStatus {
    pub sensor: u16,
    pub health: &'static str,
}

/// The latest shape for the view: `latest.glb`'s bytes, and the shape and its reference as
/// JSON (`GET /monitor.json`): `{ "t_s", "curves": [{ "curve", "points": [[x, y, z]…],
/// "displacement_m": [d…] | null }], "reference": [{ "curve", "points" }] }`, points in the
/// glTF frame with the anchor node at the origin.
#[derive(Debug, Clone)]
pub struct LatestShape {
    pub t_s: f64,
    pub glb: Vec<u8>,
    pub json: String,
}

/// How a monitor starts in its directory.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Begin {
    /// Afresh: `metrics.csv`, its rotated files, `events.log` and (unless a reference file is
    /// configured) `reference.json` of an earlier run there are removed.
    Fresh,
    /// Continuing a stopped session whose capture is fed again from its start: epochs up to
    /// the last line of `metrics.csv` rebuild the state (reference, alarms, smoothing) without
    /// writing anything; the reference it kept (`reference.json`) is the reference, unless
    /// the configuration names one.
    Resume,
}

/// The monitoring state of a session.
pub struct Monitor {
    cfg: MonitorConfig,
    dir: PathBuf,
    rec: EpochReconstructor,
    surfacer: sfs_geometry::surface::fit::Surfacer,
    reference: ReferenceBuilder,
    reference_epochs: usize,
    /// The reference once complete (from the configuration, or built).
    fixed: Option<Shape>,
    /// The structure's frame from the sensors' world frame (east, north, up).
    frame: UnitQuaternion<f64>,
    alarms: Vec<Alarm>,
    /// Each sensor's smoothed orientation (with `smoothing_s`).
    smoothed: BTreeMap<u16, UnitQuaternion<f64>>,
    /// Orientations (and flags) by sensor of the windows not yet closed, by window number.
    open: BTreeMap<i64, BTreeMap<u16, (UnitQuaternion<f64>, u8)>>,
    /// The newest window closed.
    closed: Option<i64>,
    /// The sensor ids of the layout.
    known: std::collections::BTreeSet<u16>,
    /// The layout's sensors left out at the last epoch, and why.
    health: BTreeMap<u16, &'static str>,
    /// Per sensor, the log's budget of health changes: the minute's start (session time),
    /// changes logged in it, changes not logged since the last logged one.
    health_logged: BTreeMap<u16, (f64, u32, u32)>,
    /// Outputs failing (said once while it lasts).
    output_failing: std::collections::BTreeSet<&'static str>,
    /// Why the latest surface could not be made.
    surface_error: Option<String>,
    /// Epochs failing since, and why.
    failing: Option<(f64, String)>,
    /// Consecutive epochs with a sensor of the layout left out (0: every sensor in).
    left_out_streak: i64,
    csv: Option<std::fs::File>,
    csv_bytes: u64,
    /// Resume: epochs up to this time were written by the session before (quiet replay).
    quiet_until: Option<f64>,
    /// Resume: the alarms raised at the last line written before, restored when the quiet
    /// replay ends (a rotated capture may not go back far enough to rebuild them).
    resume_alarms: Option<Vec<String>>,
    pub report: MonitorReport,
    /// The Prometheus metrics of the latest epoch (served by the view's server).
    pub metrics: crate::metrics::MonitorMetrics,
    /// Session time of the latest epoch reconstructed.
    last_t: Option<f64>,
    /// Whether a view is shown (the latest shape is kept for it), and the shape not yet taken.
    for_view: bool,
    latest: Option<LatestShape>,
}

impl Monitor {
    /// Starts monitoring into `dir`.
    pub fn new(cfg: MonitorConfig, dir: &Path, begin: Begin) -> std::io::Result<Monitor> {
        let alarms = cfg
            .alarms
            .iter()
            .map(|a| Alarm::new(a.metric, a.threshold, a.hysteresis))
            .collect();
        let reference_epochs = ((cfg.reference_s * cfg.epoch_hz).round() as usize).max(1);
        let mut m = Monitor {
            dir: dir.to_owned(),
            rec: EpochReconstructor::new(),
            surfacer: Default::default(),
            reference: ReferenceBuilder::new(),
            reference_epochs,
            fixed: cfg.reference.clone(),
            frame: UnitQuaternion::from_axis_angle(
                &nalgebra::Vector3::z_axis(),
                (cfg.x_azimuth_deg - 90.0).to_radians(),
            ),
            quiet_until: None,
            resume_alarms: None,
            alarms,
            open: BTreeMap::new(),
            closed: None,
            known: cfg.layout.sensors.iter().map(|s| s.sensor).collect(),
            health: BTreeMap::new(),
            failing: None,
            left_out_streak: 0,
            output_failing: Default::default(),
            surface_error: None,
            health_logged: BTreeMap::new(),
            smoothed: BTreeMap::new(),
            csv: None,
            csv_bytes: 0,
            report: MonitorReport::default(),
            metrics: Default::default(),
            last_t: None,
            for_view: false,
            latest: None,
            cfg,
        };
        match begin {
            Begin::Fresh => {
                for k in 1..=m.cfg.metrics_keep {
                    remove_if_present(&dir.join(format!("metrics.{k}.csv")))?;
                    remove_if_present(&dir.join(format!("events.{k}.log")))?;
                }
                remove_if_present(&dir.join(METRICS_FILE))?;
                remove_if_present(&dir.join(EVENTS_FILE))?;
                // A configured reference may be this very file: kept then (it is not rebuilt).
                if m.cfg.reference.is_none() {
                    remove_if_present(&dir.join(REFERENCE_FILE))?;
                }
            }
            Begin::Resume => {
                if let Some((t, alarms)) = last_metrics_line(&dir.join(METRICS_FILE))? {
                    m.quiet_until = Some(t);
                    m.resume_alarms = Some(alarms);
                }
                if m.fixed.is_none() {
                    if let Some((r, epochs)) = m.kept_reference() {
                        m.fixed = Some(r);
                        m.report.reference_epochs = epochs;
                    }
                }
            }
        }
        m.open_csv()?;
        Ok(m)
    }

    /// Keeps the latest shape for a view ([`take_latest`](Self::take_latest)).
    pub fn show(&mut self) {
        self.for_view = true;
    }

    /// The latest shape written to `latest.glb` since the last call, for the view.
    pub fn take_latest(&mut self) -> Option<LatestShape> {
        self.latest.take()
    }

    /// What the view shows now.
    pub fn status(&self) -> MonitorStatus {
        let ready = self.fixed.is_some();
        MonitorStatus {
            epoch_t_s: self.last_t,
            epochs: self.report.epochs,
            failed: self.report.failed,
            failing: self
                .failing
                .as_ref()
                .map(|(since, why)| format!("since t = {since:.2} s: {why}")),
            reference_epochs: if ready {
                self.report.reference_epochs
            } else {
                self.reference.count()
            },
            reference_of: self.reference_epochs,
            reference_ready: ready,
            last: self.report.last,
            alarms: self
                .alarms
                .iter()
                .map(|a| AlarmStatus {
                    metric: a.metric.name(),
                    threshold: a.threshold,
                    raised: a.is_raised(),
                })
                .collect(),
            sensors: self
                .known
                .iter()
                .map(|&sensor| SensorStatus {
                    sensor,
                    health: self.health.get(&sensor).copied().unwrap_or("ok"),
                })
                .collect(),
            unknown_sensors: self.report.unknown_sensors.clone(),
        }
    }

    /// The JSON of [`LatestShape`]: `now` and the reference (the fixed one, or the mean so far).
    fn shape_json(&self, t: f64, now: &Shape) -> String {
        let reference = self.fixed.clone().or_else(|| self.reference.reference());
        let pts = |p: &[nalgebra::Vector3<f64>]| -> Vec<[f32; 3]> {
            p.iter().map(crate::gltf_out::to_gltf).collect()
        };
        let curves: Vec<serde_json::Value> = now
            .curves
            .iter()
            .map(|(index, p)| {
                let r = reference
                    .as_ref()
                    .and_then(|r| r.points_like(*index, p.len()));
                let d = r.map(|r| {
                    p.iter()
                        .zip(r)
                        .map(|(a, b)| (a - b).norm() as f32)
                        .collect::<Vec<f32>>()
                });
                serde_json::json!({ "curve": index, "points": pts(p), "displacement_m": d })
            })
            .collect();
        let reference: Vec<serde_json::Value> = reference
            .iter()
            .flat_map(|r| &r.curves)
            .map(|(index, p)| serde_json::json!({ "curve": index, "points": pts(p) }))
            .collect();
        serde_json::json!({ "t_s": t, "curves": curves, "reference": reference }).to_string()
    }

    /// Resume: the session time from which the capture must be fed again to rebuild the
    /// state (a little before the last metrics line, for the windows and the smoothing);
    /// `None`: from its start (no metrics yet, or a reference still being built).
    pub fn replay_from(&self) -> Option<f64> {
        let q = self.quiet_until?;
        self.fixed.as_ref()?;
        Some(q - 2.0 / self.cfg.epoch_hz - 5.0 * self.cfg.smoothing_s)
    }

    /// The reference a stopped session kept, if it is there and fits the layout (and the
    /// epochs averaged into it).
    fn kept_reference(&self) -> Option<(Shape, usize)> {
        let path = self.dir.join(REFERENCE_FILE);
        let text = std::fs::read_to_string(&path).ok()?;
        let step = EpochParams::default().step;
        let shape = super::metrics::ReferenceFile::parse(&text)
            .and_then(|r| {
                if r.anchor == self.cfg.anchor {
                    Ok((
                        r.shape(&self.cfg.layout.curves, step)?,
                        r.epochs.unwrap_or(0),
                    ))
                } else {
                    Err(super::metrics::ReferenceError::Anchored { anchor: r.anchor })
                }
            })
            .map_err(|e| {
                tracing::warn!(
                    "monitor: {}: {e}; the reference is built again",
                    path.display()
                )
            })
            .ok()?;
        tracing::info!("monitor: resumed with the reference of {}", path.display());
        Some(shape)
    }

    fn open_csv(&mut self) -> std::io::Result<()> {
        let path = self.dir.join(METRICS_FILE);
        let mut f = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&path)?;
        self.csv_bytes = f.metadata()?.len();
        if self.csv_bytes == 0 {
            f.write_all(CSV_HEADER.as_bytes())?;
            self.csv_bytes = CSV_HEADER.len() as u64;
        }
        self.csv = Some(f);
        Ok(())
    }

    /// Rotates `metrics.csv` → `metrics.1.csv` → … keeping `metrics_keep` old files.
    fn rotate(&mut self) -> std::io::Result<()> {
        self.csv = None;
        rotate_file(&self.dir, METRICS_FILE, self.cfg.metrics_keep)?;
        self.open_csv()
    }

    /// The outcome of writing output `what`: an error is logged when that output starts
    /// failing (not at every epoch: a full disk must not also flood the log), and its
    /// recovery.
    fn output(&mut self, what: &'static str, r: Result<(), impl std::fmt::Display>) {
        match r {
            Ok(()) => {
                if self.output_failing.remove(what) {
                    tracing::info!("monitor: {what} written again");
                }
            }
            Err(e) => {
                if self.output_failing.insert(what) {
                    tracing::error!("monitor: {what}: {e} (said once while it lasts)");
                }
            }
        }
    }

    /// Appends `line` to `events.log` (rotated as `metrics.csv` is, past the same size) and
    /// syncs it.
    fn event(&mut self, line: &str) {
        let path = self.dir.join(EVENTS_FILE);
        let size = std::fs::metadata(&path).map_or(0, |m| m.len());
        let rotated = if size + line.len() as u64 > self.cfg.metrics_max_bytes {
            rotate_file(&self.dir, EVENTS_FILE, self.cfg.metrics_keep)
        } else {
            Ok(())
        };
        let written = rotated
            .and_then(|()| {
                std::fs::OpenOptions::new()
                    .create(true)
                    .append(true)
                    .open(&path)
            })
            .and_then(|mut f| f.write_all(line.as_bytes()).and_then(|_| f.sync_data()));
        self.output(EVENTS_FILE, written);
    }

    /// Feeds one sensor's epoch; windows older than the newest one seen are closed. An epoch
    /// of a window already closed is ignored (counted as late).
    pub fn feed(&mut self, e: &ArrayEpoch) {
        if !self.known.contains(&e.sensor) {
            if let Err(k) = self.report.unknown_sensors.binary_search(&e.sensor) {
                // Once, for the first: a wrong layout would say it for every sensor. The end
                // of the session says which (one warning for all, in the report too).
                if self.report.unknown_sensors.is_empty() {
                    tracing::warn!(
                        "monitor: sensor {} streams but the layout does not place it; ignored (any other such sensor is listed when the session ends)",
                        e.sensor
                    );
                } else {
                    tracing::debug!("monitor: sensor {} not in the layout either", e.sensor);
                }
                self.report.unknown_sensors.insert(k, e.sensor);
            }
            return;
        }
        let key = (e.t * self.cfg.epoch_hz).round() as i64;
        if self.closed.is_some_and(|c| key <= c) {
            self.report.late += 1;
            tracing::debug!(
                "monitor: sensor {} reported the window ending at t = {:.2} s after it closed; ignored",
                e.sensor,
                e.t
            );
            return;
        }
        let q = UnitQuaternion::from_quaternion(Quaternion::new(e.q[0], e.q[1], e.q[2], e.q[3]));
        self.open
            .entry(key)
            .or_default()
            .insert(e.sensor, (q, e.flags));
        while self.open.len() > 1 {
            let (&k, _) = self.open.iter().next().expect("two windows");
            if k >= key {
                break;
            }
            let window = self.open.remove(&k).expect("present");
            self.closed = Some(k);
            self.close(k as f64 / self.cfg.epoch_hz, window);
        }
    }

    /// Closes the open windows that end by `t` (every sensor has reported them: see
    /// [`crate::acquisition::Acquisition::array_complete_until`]), without waiting for the
    /// next window's epochs: the metrics, alarms and latest shape of an epoch come as soon as
    /// it ends.
    pub fn close_until(&mut self, t: f64) {
        let last = (t * self.cfg.epoch_hz + 1e-6).floor() as i64;
        while let Some((&k, _)) = self.open.iter().next() {
            if k > last {
                break;
            }
            let window = self.open.remove(&k).expect("present");
            self.closed = Some(k);
            self.close(k as f64 / self.cfg.epoch_hz, window);
        }
    }

    /// The one warning for every sensor that streamed and that the layout does not place.
    pub fn unknown_sensors(&self) -> Option<crate::warning::Warning> {
        (!self.report.unknown_sensors.is_empty()).then(|| crate::warning::Warning::UnknownSensors {
            sensors: self.report.unknown_sensors.clone(),
            placed: self.known.iter().copied().collect(),
            none_placed: self.report.epochs == 0,
        })
    }

    /// Closes the windows still open (end of the session).
    pub fn finish(&mut self) {
        for (k, w) in std::mem::take(&mut self.open) {
            self.close(k as f64 / self.cfg.epoch_hz, w);
        }
        if self.report.epochs == 0 && self.report.unknown_sensors.is_empty() {
            tracing::warn!(
                "monitor: no epoch: the stream held no sensor-array samples (monitoring needs a device of kind 3, see report.json \"link\" → \"hello\")"
            );
        }
        crate::memory::release_free_memory();
        self.report.rss_mb = crate::memory::rss_mb().0;
        if let Some(f) = &mut self.csv {
            let _ = f.sync_data();
        }
    }

    /// Updates the Prometheus metrics (gauges of the latest epoch, counters of the session).
    fn expose(&self, t: f64, m: &Metrics, missing: usize, saturated: usize, disturbed: usize) {
        use crate::metrics::count_to;
        let x = &self.metrics;
        x.epoch_time.set(t);
        count_to(&x.epochs, self.report.epochs);
        count_to(&x.epochs_failed, self.report.failed);
        count_to(&x.epochs_late, self.report.late);
        x.sensors_unknown
            .set(self.report.unknown_sensors.len() as i64);
        x.max_displacement.set(m.max_displacement);
        x.mean_displacement.set(m.mean_displacement);
        x.max_curvature_change.set(m.max_curvature_change);
        x.sensors_missing.set(missing as i64);
        x.sensors_saturated.set(saturated as i64);
        x.sensors_disturbed.set(disturbed as i64);
        x.sensors_left_out_epochs.set(self.left_out_streak);
        count_to(&x.alarms_raised, self.report.alarms_raised);
        for a in &self.alarms {
            let labels = vec![
                ("metric".to_string(), a.metric.to_string()),
                ("threshold".to_string(), a.threshold.to_string()),
            ];
            x.alarm.get_or_create(&labels).set(i64::from(a.is_raised()));
        }
        x.sensor_left_out.clear();
        for (sensor, reason) in &self.health {
            let labels = vec![
                ("sensor".to_string(), sensor.to_string()),
                ("reason".to_string(), reason.to_string()),
            ];
            x.sensor_left_out.get_or_create(&labels).set(1);
        }
    }

    /// An epoch that cannot be reconstructed: counted, and a warning when it starts failing or
    /// the reason changes (not one per epoch: an unattended log must not fill the disk).
    fn failed(&mut self, t: f64, why: String) {
        self.report.failed += 1;
        if self.failing.as_ref().is_none_or(|(_, w)| *w != why) {
            tracing::warn!("monitor: epoch at t = {t:.2} s: {why} (said once while it lasts)");
            self.failing = Some((t, why));
        }
    }

    /// Per-sensor health: a line in `events.log` when a sensor of the layout is left out
    /// (missing, saturated, disturbed) or back (`ok`); in the log too, at most four changes a
    /// minute per sensor (a flapping sensor must not flood it; the next line says how many
    /// were not logged). `health`: the sensors left out this epoch.
    fn health_changes(&mut self, t: f64, health: BTreeMap<u16, &'static str>, quiet: bool) {
        if health == self.health {
            return;
        }
        let mut changes = Vec::new();
        for (s, now) in &health {
            if self.health.get(s) != Some(now) {
                changes.push((*s, *now));
            }
        }
        for s in self.health.keys().filter(|s| !health.contains_key(s)) {
            changes.push((*s, "ok"));
        }
        let mut lines = Vec::new();
        for (s, now) in changes {
            lines.push(format!("t={t:.3} sensor {s} {now}\n"));
            if quiet {
                continue;
            }
            // (start of the minute, changes logged in it, changes not logged since)
            let slot = self.health_logged.entry(s).or_insert((t, 0, 0));
            if t - slot.0 >= 60.0 {
                (slot.0, slot.1) = (t, 0);
            }
            if slot.1 >= 4 {
                slot.2 += 1;
                continue;
            }
            slot.1 += 1;
            let skipped = std::mem::take(&mut slot.2);
            let more = if skipped > 0 {
                format!(" ({skipped} changes before not logged; all are in {EVENTS_FILE})")
            } else {
                String::new()
            };
            if now == "ok" {
                tracing::info!(sensor = s, "monitor: t = {t:.2} s: sensor {s} ok{more}");
            } else {
                tracing::warn!(sensor = s, "monitor: t = {t:.2} s: sensor {s} {now}{more}");
            }
        }
        self.health = health;
        if !quiet {
            for l in lines {
                self.event(&l);
            }
        }
    }

    /// The reference is complete: kept, and written as `reference.json`.
    fn keep_reference(&mut self, r: Shape) {
        let file = super::metrics::ReferenceFile::from_shape(
            &r,
            self.cfg.anchor,
            Some(self.reference.count()),
        );
        let path = self.dir.join(REFERENCE_FILE);
        match crate::atomic::write_json(&path, &file, false) {
            Ok(()) => tracing::info!(
                "monitor: reference of {} epochs written to {}",
                self.reference.count(),
                path.display()
            ),
            Err(e) => tracing::error!("monitor: {}: {e}", path.display()),
        }
        self.fixed = Some(r);
        self.reference = ReferenceBuilder::new();
    }

    /// Closes the epoch ending at `t` with the sensors' orientations of its `window`: the
    /// shape is reconstructed, measured against the reference, the alarms updated, and the
    /// outputs written (a metrics line, every `latest_every` epochs `latest.glb`).
    fn close(&mut self, t: f64, window: BTreeMap<u16, (UnitQuaternion<f64>, u8)>) {
        let started = std::time::Instant::now();
        let quiet = self.begin_epoch(t);
        let usable = self.usable_orientations(&window);
        let shape = match self.rec.run(
            &self.cfg.layout,
            &usable,
            &EpochParams {
                regression: self.cfg.regression,
                ..Default::default()
            },
        ) {
            Ok(s) => s,
            Err(e) => return self.failed(t, e.to_string()),
        };
        let (missing, saturated, disturbed) = self.health(t, &shape.missing, &window, quiet);
        self.left_out_streak = match missing + saturated + disturbed {
            0 => 0,
            _ => self.left_out_streak + 1,
        };
        for w in &shape.left_out {
            tracing::debug!("monitor: t = {t:.2} s: {w}");
        }
        let Some(now) = Shape::anchored(&shape.positions, self.cfg.anchor) else {
            let why = format!(
                "the anchor node {} is on no curve with a sensor",
                self.cfg.anchor
            );
            return self.failed(t, why);
        };
        if let Some((since, _)) = self.failing.take() {
            tracing::info!("monitor: epochs reconstructed again from t = {t:.2} s (failing since {since:.2} s)");
        }
        let metrics = self.measure(&now);
        self.last_t = Some(t);
        let raised = self.update_alarms(t, &metrics, quiet);
        let line = format!(
            "{t:.3},{:.6},{:.6},{:.6},{},{saturated},{disturbed},{}\n",
            metrics.max_displacement,
            metrics.mean_displacement,
            metrics.max_curvature_change,
            missing,
            raised.join(";")
        );
        self.report.last = Some(metrics);
        self.expose(t, &metrics, missing, saturated, disturbed);
        if quiet {
            return;
        }
        self.write_metrics_line(&line);
        if self
            .report
            .epochs
            .is_multiple_of(self.cfg.latest_every as u64)
        {
            if let Some(glb) = self.write_latest(t, &shape.positions) {
                if self.for_view {
                    let json = self.shape_json(t, &now);
                    self.latest = Some(LatestShape { t_s: t, glb, json });
                }
            }
        }
        self.metrics
            .epoch_latency
            .set(started.elapsed().as_secs_f64());
    }

    /// Counts the epoch; whether it is a quiet one (a resumed session feeding again what its
    /// files already hold); restores the alarms of a resumed session at its first new epoch;
    /// notes the memory after the first hour.
    fn begin_epoch(&mut self, t: f64) -> bool {
        self.report.epochs += 1;
        // Written as `{t:.3}` by the session before.
        let quiet = self.quiet_until.is_some_and(|q| t <= q + 5e-4);
        if !quiet {
            if let Some(raised) = self.resume_alarms.take() {
                for a in &mut self.alarms {
                    a.set_raised(raised.contains(&a.label()));
                }
            }
        }
        if t >= 3600.0 && self.report.rss_mb_after_first_hour.is_none() {
            crate::memory::release_free_memory();
            self.report.rss_mb_after_first_hour = crate::memory::rss_mb().0;
        }
        quiet
    }

    /// The orientations of the sensors whose window is usable, in the structure's frame,
    /// smoothed across epochs when configured. Saturated and magnetically disturbed sensors
    /// are left out like missing ones (their curve is interpolated across them): a disturbed
    /// magnetometer turns the heading.
    fn usable_orientations(
        &mut self,
        window: &BTreeMap<u16, (UnitQuaternion<f64>, u8)>,
    ) -> BTreeMap<u16, UnitQuaternion<f64>> {
        let unusable = flags::INVALID | flags::SATURATED | flags::MAG_DISTURBED;
        let mut usable: BTreeMap<u16, UnitQuaternion<f64>> = window
            .iter()
            .filter(|(_, (_, f))| f & unusable == 0)
            .map(|(s, (q, _))| (*s, self.frame * q))
            .collect();
        if self.cfg.smoothing_s > 0.0 {
            // First-order smoothing on SO(3): slerp from the last smoothed orientation
            // towards the new one by 1 − exp(−Δt/τ).
            let a = 1.0 - (-1.0 / (self.cfg.epoch_hz * self.cfg.smoothing_s)).exp();
            for (s, q) in usable.iter_mut() {
                let prev = self.smoothed.get(s).copied().unwrap_or(*q);
                *q = prev.try_slerp(q, a, 1e-9).unwrap_or(*q);
                self.smoothed.insert(*s, *q);
            }
        }
        usable
    }

    /// Each sensor of the layout left out, counted once: saturated, else disturbed, else
    /// missing (no samples, or no orientation from them); the changes are reported.
    fn health(
        &mut self,
        t: f64,
        left_out: &[u16],
        window: &BTreeMap<u16, (UnitQuaternion<f64>, u8)>,
        quiet: bool,
    ) -> (usize, usize, usize) {
        let (mut missing, mut saturated, mut disturbed) = (0, 0, 0);
        let mut health = BTreeMap::new();
        for s in left_out {
            let state = match window.get(s).map(|(_, f)| *f) {
                Some(f) if f & flags::SATURATED != 0 => {
                    saturated += 1;
                    "saturated"
                }
                Some(f) if f & flags::MAG_DISTURBED != 0 => {
                    disturbed += 1;
                    "disturbed"
                }
                _ => {
                    missing += 1;
                    "missing"
                }
            };
            health.insert(*s, state);
        }
        self.health_changes(t, health, quiet);
        (missing, saturated, disturbed)
    }

    /// The metrics of shape `now` against the reference (the fixed one, or the mean of the
    /// first epochs, which `now` joins while it is being built).
    fn measure(&mut self, now: &Shape) -> Metrics {
        match &self.fixed {
            Some(r) => compare(r, now),
            None => {
                if self.reference.add(now) {
                    self.report.reference_epochs = self.reference.count();
                }
                let r = self.reference.reference().expect("an epoch was added");
                let m = compare(&r, now);
                if self.reference.count() >= self.reference_epochs {
                    self.keep_reference(r);
                }
                m
            }
        }
    }

    /// Feeds the epoch's metrics to the alarms: transitions are logged and written to
    /// `events.log` (not in a quiet epoch); the labels of the alarms raised.
    fn update_alarms(&mut self, t: f64, metrics: &Metrics, quiet: bool) -> Vec<String> {
        let mut raised = Vec::new();
        let mut lines = Vec::new();
        for a in &mut self.alarms {
            let value = a.metric.of(metrics);
            let tr = a.update(value);
            if tr == Some(Transition::Raised) {
                self.report.alarms_raised += 1;
            }
            if let Some(tr) = tr.filter(|_| !quiet) {
                let what = match tr {
                    Transition::Raised => "raised",
                    Transition::Cleared => "cleared",
                };
                tracing::warn!(
                    metric = a.metric.name(),
                    value,
                    threshold = a.threshold,
                    "monitor: alarm {what} at t = {t:.2} s"
                );
                let line = format!(
                    "t={t:.3} alarm {what} {}={value:.4} threshold={}\n",
                    a.metric, a.threshold
                );
                lines.push(line);
            }
            if a.is_raised() {
                raised.push(a.label());
            }
        }
        for l in lines {
            self.event(&l);
        }
        raised
    }

    /// Appends `line` to `metrics.csv`, rotated past its size (opened again after a failed
    /// rotation or write).
    fn write_metrics_line(&mut self, line: &str) {
        let written = if self.csv_bytes + line.len() as u64 > self.cfg.metrics_max_bytes {
            self.rotate()
        } else if self.csv.is_none() {
            // A rotation or an earlier write failed: opened again.
            self.open_csv()
        } else {
            Ok(())
        }
        .and_then(|()| match &mut self.csv {
            Some(f) => f.write_all(line.as_bytes()),
            None => Err(std::io::Error::other("not open")),
        });
        match written {
            Ok(()) => self.csv_bytes += line.len() as u64,
            Err(_) => self.csv = None,
        }
        self.output(METRICS_FILE, written);
    }

    /// Replaces `latest.glb` with the shape (and its surface when configured); its bytes.
    fn write_latest(
        &mut self,
        t: f64,
        positions: &sfs_geometry::network::poisson::Positions,
    ) -> Option<Vec<u8>> {
        let surface = self.cfg.surface.as_ref().and_then(|sp| {
            let (result, ms) = crate::pipeline::surface_of(positions, sp, &mut self.surfacer);
            match result {
                Ok(s) => {
                    self.report.surfaces += 1;
                    self.report.surface_ms = Some(ms);
                    self.report.surface_factorisations = self.surfacer.numeric_factorisations();
                    Some(s)
                }
                Err(e) => {
                    self.report.surfaces_failed += 1;
                    self.surface_error = Some(format!("t = {t:.2} s: {e}"));
                    None
                }
            }
        });
        let glb = crate::pipeline::glb(positions, surface.as_ref());
        if let Some(e) = self.surface_error.take() {
            self.output("the surface", Err(e));
        } else if self.cfg.surface.is_some() {
            self.output("the surface", Ok::<(), String>(()));
        }
        let path = self.dir.join(LATEST_FILE);
        let glb = glb.map_err(|e| e.to_string());
        let written = glb
            .as_ref()
            .map_err(Clone::clone)
            .and_then(|b| crate::atomic::write_atomic(&path, b).map_err(|e| e.to_string()));
        self.output(LATEST_FILE, written);
        glb.ok()
    }
}
