//! `sfs ports`: the serial ports of this machine with their USB identity, and which of them
//! speak this protocol.
//!
//! The list is serialport's (`available_ports`, built without libudev: it reads the USB
//! vendor and product ids, manufacturer, product and serial number from sysfs). A probe opens
//! a port for a short time and decodes what arrives: the device's HELLO (kind, id, firmware,
//! rate), or, since HELLO comes only every 5 s, at least valid packets of this protocol. A
//! port that cannot be opened says why, naming the group to join when it is a question of
//! permissions.
//!
//! ```no_run
//! let ports = sfs::ports::list();
//! for p in &ports {
//!     let probe = sfs::ports::probe(std::path::Path::new(&p.path), 115_200,
//!         std::time::Duration::from_secs(2));
//!     println!("{} {:?}", p.path, probe);
//! }
//! ```

use device_protocol::{Decoder, Event, Packet};
use serde::Serialize;
use std::io::Read;
use std::path::Path;
use std::time::{Duration, Instant};

/// A serial port and how it is attached.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PortInfo {
    /// Its device path (`/dev/ttyUSB0`).
    pub path: String,
    /// `usb`, `pci`, `bluetooth`, `unknown`.
    pub kind: &'static str,
    /// The USB identity, for a USB port.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub usb: Option<UsbIdentity>,
}

/// What a USB serial adapter says it is.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct UsbIdentity {
    /// `VID:PID` in hexadecimal (`0403:6001`).
    pub id: String,
    pub manufacturer: Option<String>,
    pub product: Option<String>,
    pub serial: Option<String>,
}

/// The serial ports the system lists, by path (none when the system has no `/sys/class/tty`).
pub fn list() -> Vec<PortInfo> {
    // serialport panics when sysfs has no tty class (a container without /sys).
    if !Path::new("/sys/class/tty").is_dir() {
        return Vec::new();
    }
    let mut ports: Vec<PortInfo> = match serialport::available_ports() {
        Ok(p) => p.into_iter().map(info).collect(),
        Err(e) => {
            tracing::warn!("cannot list the serial ports: {e}");
            Vec::new()
        }
    };
    ports.sort_by(|a, b| a.path.cmp(&b.path));
    ports
}

fn info(p: serialport::SerialPortInfo) -> PortInfo {
    use serialport::SerialPortType as T;
    let (kind, usb) = match p.port_type {
        T::UsbPort(u) => (
            "usb",
            Some(UsbIdentity {
                id: format!("{:04x}:{:04x}", u.vid, u.pid),
                manufacturer: u.manufacturer,
                product: u.product,
                serial: u.serial_number,
            }),
        ),
        T::PciPort => ("pci", None),
        T::BluetoothPort => ("bluetooth", None),
        T::Unknown => ("unknown", None),
    };
    PortInfo {
        path: p.port_name,
        kind,
        usb,
    }
}

/// The udev rule (deploy/99-sfs.rules) that names the adapter `/dev/sfs-<kind>-<serial>`,
/// for a USB port whose device said what it is.
pub fn udev_rule(usb: &UsbIdentity, device: &str) -> Option<String> {
    let (vid, pid) = usb.id.split_once(':')?;
    let serial = usb.serial.as_deref().filter(|s| !s.is_empty())?;
    let name: String = serial
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect();
    let quoted = serial.replace('"', "");
    Some(format!(
        "SUBSYSTEM==\"tty\", ATTRS{{idVendor}}==\"{vid}\", ATTRS{{idProduct}}==\"{pid}\", ATTRS{{serial}}==\"{quoted}\", SYMLINK+=\"sfs-{device}-{name}\", GROUP=\"dialout\", MODE=\"0660\", TAG+=\"systemd\""
    ))
}

/// What a probe of a port found.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "result", rename_all = "snake_case")]
pub enum Probe {
    /// The device introduced itself.
    Hello {
        device: &'static str,
        device_id: u32,
        firmware: u16,
        rate_hz: u16,
        protocol: u8,
    },
    /// Valid packets of this protocol but no HELLO in the time given (it comes every 5 s).
    Speaks { packets: usize },
    /// Bytes, but no valid packet of this protocol (another device, or another speed).
    Other { bytes: usize },
    /// Nothing arrived.
    Silent,
    /// The port cannot be opened by this user: the group owning it (to join), if known.
    PermissionDenied { group: Option<String> },
    /// Another program holds the port (a running `sfs`?).
    Busy,
    /// It could not be opened for another reason.
    Failed { reason: String },
}

impl std::fmt::Display for Probe {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Probe::Hello {
                device,
                device_id,
                firmware,
                rate_hz,
                protocol,
            } => write!(
                f,
                "{device} id {device_id}, firmware {firmware}, {rate_hz} Hz (protocol {protocol})"
            ),
            Probe::Speaks { packets } => write!(
                f,
                "speaks protocol 1 ({packets} packets; no HELLO yet: it comes every 5 s, probe longer to see the device)"
            ),
            Probe::Other { bytes } => {
                write!(f, "{bytes} bytes, none of them packets of this protocol (another device or speed)")
            }
            Probe::Silent => f.write_str("silent"),
            Probe::PermissionDenied { group: Some(g) } => write!(
                f,
                "permission denied: join the group {g} (sudo usermod -aG {g} $USER, then log in again), or install deploy/99-sfs.rules"
            ),
            Probe::PermissionDenied { group: None } => f.write_str("permission denied"),
            Probe::Busy => f.write_str("in use by another program (a running sfs?)"),
            Probe::Failed { reason } => write!(f, "cannot open: {reason}"),
        }
    }
}

/// Opens `path` at `baud` for at most `time` and decodes what arrives; returns at the first
/// HELLO.
pub fn probe(path: &Path, baud: u32, time: Duration) -> Probe {
    let mut port = match serialport::new(path.to_string_lossy(), baud)
        .timeout(Duration::from_millis(50))
        .open_native()
    {
        Ok(p) => p,
        Err(e) => return open_error(path, &e),
    };
    let deadline = Instant::now() + time;
    let mut decoder = Decoder::new();
    let mut buf = [0u8; 4096];
    let (mut bytes, mut packets) = (0usize, 0usize);
    while Instant::now() < deadline {
        let n = match port.read(&mut buf) {
            Ok(0) => continue,
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => continue,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => {
                return Probe::Failed {
                    reason: format!("read: {e}"),
                }
            }
        };
        bytes += n;
        for event in decoder.feed(&buf[..n]) {
            if let Event::Packet { packet, .. } = event {
                packets += 1;
                if let Packet::Hello(h) = packet {
                    return Probe::Hello {
                        device: h.kind.name(),
                        device_id: h.device_id,
                        firmware: h.firmware,
                        rate_hz: h.rate_hz,
                        protocol: h.proto,
                    };
                }
            }
        }
    }
    match (bytes, packets) {
        (0, _) => Probe::Silent,
        (b, 0) => Probe::Other { bytes: b },
        (_, p) => Probe::Speaks { packets: p },
    }
}

fn open_error(path: &Path, e: &serialport::Error) -> Probe {
    use serialport::ErrorKind as K;
    match e.kind() {
        K::Io(std::io::ErrorKind::PermissionDenied) => Probe::PermissionDenied {
            group: owning_group(path),
        },
        K::NoDevice
            if ["busy", "lock"]
                .iter()
                .any(|w| e.to_string().to_lowercase().contains(w)) =>
        {
            Probe::Busy
        }
        _ => Probe::Failed {
            reason: e.to_string(),
        },
    }
}

/// The name of the group that owns `path` (`dialout`, or the one a udev rule set).
pub fn owning_group(path: &Path) -> Option<String> {
    use std::os::unix::fs::MetadataExt;
    let gid = std::fs::metadata(path).ok()?.gid();
    let groups = std::fs::read_to_string("/etc/group").ok()?;
    group_name(&groups, gid)
}

/// The name of group `gid` in the text of `/etc/group` (`name:password:gid:members`).
fn group_name(etc_group: &str, gid: u32) -> Option<String> {
    etc_group.lines().find_map(|line| {
        let mut f = line.split(':');
        let name = f.next()?;
        let id: u32 = f.nth(1)?.trim().parse().ok()?;
        (id == gid && !name.is_empty()).then(|| name.to_owned())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_udev_rule_names_the_adapter_by_kind_and_serial() {
        let usb = UsbIdentity {
            id: "0403:6015".into(),
            manufacturer: Some("FTDI".into()),
            product: None,
            serial: Some("DK0A/9 Z".into()),
        };
        let rule = udev_rule(&usb, "morphorider").unwrap();
        assert!(
            rule.contains(r#"ATTRS{idVendor}=="0403", ATTRS{idProduct}=="6015""#),
            "{rule}"
        );
        assert!(rule.contains(r#"ATTRS{serial}=="DK0A/9 Z""#), "{rule}");
        assert!(
            rule.contains(r#"SYMLINK+="sfs-morphorider-DK0A_9_Z""#),
            "{rule}"
        );
        assert!(rule.contains(r#"GROUP="dialout", MODE="0660""#), "{rule}");
        // No serial number: no stable name to give.
        let anonymous = UsbIdentity {
            serial: None,
            ..usb
        };
        assert_eq!(udev_rule(&anonymous, "phone"), None);
    }

    #[test]
    fn group_names_come_from_etc_group() {
        let text = "root:x:0:\ndialout:x:20:alice,bob\n# comment\nbroken\nsfs:x:998:\n";
        assert_eq!(group_name(text, 20).as_deref(), Some("dialout"));
        assert_eq!(group_name(text, 998).as_deref(), Some("sfs"));
        assert_eq!(group_name(text, 5), None);
    }

    #[test]
    fn a_permission_error_names_the_group_to_join() {
        let p = Probe::PermissionDenied {
            group: Some("dialout".into()),
        };
        let text = p.to_string();
        assert!(text.contains("join the group dialout"), "{text}");
        assert!(text.contains("usermod -aG dialout"), "{text}");
        let e = serialport::Error::new(
            serialport::ErrorKind::Io(std::io::ErrorKind::PermissionDenied),
            "Permission denied",
        );
        // /dev/null is owned by root's group.
        assert_eq!(
            open_error(Path::new("/dev/null"), &e),
            Probe::PermissionDenied {
                group: owning_group(Path::new("/dev/null"))
            }
        );
    }
}
