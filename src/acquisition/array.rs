//! Sensor arrays (monitoring): every sensor's samples averaged over windows of a grid of
//! session time shared by all sensors, each window giving one epoch (TRIAD of the mean
//! acceleration and field, flagged).

use super::{quat_array, Acquisition};
use crate::orientation::disturbance::acc_motion;
use crate::orientation::flags;
use crate::orientation::triad::triad;
use crate::scan::ArrayEpoch;
use nalgebra::{UnitQuaternion, Vector3};

#[derive(Debug, Clone, Default)]
pub(super) struct ArraySensor {
    /// The window being averaged: `[window · W, (window + 1) · W)` of session time.
    window: i64,
    acc: Vector3<f64>,
    mag: Vector3<f64>,
    n: u32,
    flags: u8,
    /// Session time of its newest sample, s.
    last_t: f64,
}

impl Acquisition {
    /// Sensor arrays: the session time up to which every sensor's windows are complete (the
    /// start of the newest window a sample fell in); `None` before the first sample.
    pub fn array_complete_until(&self) -> Option<f64> {
        self.array_grid.map(|k| k as f64 * self.cfg.array_window)
    }

    /// Takes the sensor-array epochs gathered so far (monitoring consumes them as they come,
    /// so that a month-long session does not keep them all).
    pub fn take_array(&mut self) -> Vec<ArrayEpoch> {
        std::mem::take(&mut self.scan.array)
    }

    pub(super) fn array_sample(
        &mut self,
        t: f64,
        sensor: u16,
        acc: Vector3<f64>,
        mag: Vector3<f64>,
        sat: bool,
    ) {
        // Windows on a grid of session time shared by every sensor, so that the epochs of
        // all sensors of one window carry the same time (the window's end). Samples come in
        // time order: the first of a window closes every sensor's earlier one (a sensor that
        // stops sending has its last window closed on time, not when it comes back).
        let th = self.cfg.thresholds;
        let k = (t / self.cfg.array_window).floor() as i64;
        if self.array_grid.is_none_or(|g| k > g) {
            let done: Vec<u16> = self
                .array
                .iter()
                .filter(|(_, st)| st.window < k)
                .map(|(id, _)| *id)
                .collect();
            for id in done {
                let st = self.array.remove(&id).expect("listed");
                self.close_array_window(id, st);
            }
            self.array_grid = Some(k);
        }
        let st = self.array.entry(sensor).or_insert_with(|| ArraySensor {
            window: k,
            ..Default::default()
        });
        if k < st.window {
            // Out of time order: its window is closed already.
            self.scan.counts.array_late += 1;
            return;
        }
        st.last_t = st.last_t.max(t);
        if sat {
            st.flags |= flags::SATURATED;
            return;
        }
        if acc_motion(&acc, &th) {
            st.flags |= flags::ACC_MOTION;
        } else {
            self.field.add(&acc, &mag);
        }
        st.acc += acc;
        st.mag += mag;
        st.n += 1;
    }

    /// The epoch of one sensor's finished window: its mean orientation (TRIAD of the mean
    /// acceleration and field), flagged saturated, moving or magnetically disturbed; a window
    /// whose samples were all saturated gives an epoch without orientation (so that the
    /// sensor is known saturated, not missing).
    fn close_array_window(&mut self, sensor: u16, st: ArraySensor) {
        let t = (st.window + 1) as f64 * self.cfg.array_window;
        if st.n == 0 {
            if st.flags & flags::SATURATED != 0 {
                self.scan.array.push(ArrayEpoch {
                    t,
                    sensor,
                    q: quat_array(&UnitQuaternion::identity()),
                    samples: 0,
                    flags: st.flags | flags::INVALID,
                });
            }
            return;
        }
        let (acc_mean, mag_mean) = (st.acc / st.n as f64, st.mag / st.n as f64);
        let mut f = st.flags;
        // Magnetically disturbed: the window's mean field off the site's (the median over
        // every sensor at rest so far, taken once per window) in norm or dip.
        let reference = match self.array_field {
            Some((w, r)) if w == st.window => r,
            _ => {
                let r = self.field.reference();
                self.array_field = Some((st.window, r));
                r
            }
        };
        if crate::orientation::disturbance::mag_disturbed(
            reference,
            &acc_mean,
            &mag_mean,
            &self.cfg.thresholds,
        ) {
            f |= flags::MAG_DISTURBED;
        }
        let q = match triad(&acc_mean, &mag_mean) {
            Some(q) => q,
            None => {
                f |= flags::INVALID;
                UnitQuaternion::identity()
            }
        };
        self.scan.array.push(ArrayEpoch {
            t,
            sensor,
            q: quat_array(&q),
            samples: st.n,
            flags: f,
        });
    }

    /// End of input for sensor arrays: the window of the shared grid still held is closed
    /// for every sensor, as when the grid moves on, when it is complete (its newest sample
    /// within one sample interval of its end, at the HELLO's rate); an incomplete one is
    /// dropped. Its epochs join [`take_array`](Self::take_array)'s; returns the time up to
    /// which epochs are then complete.
    pub fn close_array(&mut self) -> Option<f64> {
        let grid = self.array_grid?;
        let rate = self.scan.device.as_ref().map_or(0, |d| d.rate_hz);
        let interval = if rate > 0 { 1.0 / rate as f64 } else { 0.0 };
        let end = (grid + 1) as f64 * self.cfg.array_window;
        let newest = self
            .array
            .values()
            .map(|st| st.last_t)
            .fold(f64::MIN, f64::max);
        let held = std::mem::take(&mut self.array);
        if newest + interval < end - 1e-6 {
            return None;
        }
        for (id, st) in held {
            self.close_array_window(id, st);
        }
        self.array_grid = Some(grid + 1);
        Some(end)
    }
}
