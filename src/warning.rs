//! The warnings of a session: every problem met on the way (a keypad sequence the grammar
//! refuses, a sample stream acquisition has to bridge, a curve the reconstruction leaves out,
//! a face the surfacer cannot accept), typed, with the curve, node and time as fields where
//! they have them. Their text (`Display`) is what the log, `scan.json` and `report.json` say;
//! their [`code`](Warning::code) is a stable name of the kind, for machines.

use crate::acquisition::AcquisitionWarning;
use crate::keypad;
use sfs_geometry::network::NetworkWarning;
use sfs_geometry::surface::fit::SurfaceError;
use sfs_geometry::surface::SurfaceProblem;

/// A problem met by a session.
#[derive(Debug, Clone, PartialEq)]
pub enum Warning {
    /// A keypad sequence the grammar refuses.
    Keypad(keypad::Warning),
    /// Something acquisition had to bridge or leave out.
    Acquisition(AcquisitionWarning),
    /// The reconstruction of the network.
    Network(NetworkWarning),
    /// A problem of the surface (a face or patch left out, triangles dropped).
    Surface(SurfaceProblem),
    /// No surface at all.
    NoSurface(SurfaceError),
    /// `network.glb` could not be encoded.
    GlbNotWritten(crate::gltf_out::GltfError),
}

impl Warning {
    /// A stable name of the kind of problem.
    pub fn code(&self) -> &'static str {
        match self {
            Warning::Keypad(w) => w.issue.code(),
            Warning::Acquisition(w) => w.code(),
            Warning::Network(w) => w.code(),
            Warning::Surface(p) => p.code(),
            Warning::NoSurface(_) => "no_surface",
            Warning::GlbNotWritten(_) => "glb_not_written",
        }
    }

    /// The curve it names, by scan index.
    pub fn curve(&self) -> Option<usize> {
        match self {
            Warning::Keypad(w) => w.curve,
            Warning::Acquisition(w) => w.curve(),
            Warning::Network(w) => w.curve(),
            _ => None,
        }
    }

    /// The node it names.
    pub fn node(&self) -> Option<u32> {
        match self {
            Warning::Keypad(w) => w.node,
            Warning::Network(w) => w.node(),
            _ => None,
        }
    }
}

impl std::fmt::Display for Warning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Warning::Keypad(w) => w.fmt(f),
            Warning::Acquisition(w) => w.fmt(f),
            Warning::Network(w) => w.fmt(f),
            Warning::Surface(p) => write!(f, "surface: {p}"),
            Warning::NoSurface(e) => write!(f, "no surface: {e}"),
            Warning::GlbNotWritten(e) => write!(f, "network.glb not written: {e}"),
        }
    }
}

/// Written as its text.
impl serde::Serialize for Warning {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

impl From<keypad::Warning> for Warning {
    fn from(w: keypad::Warning) -> Self {
        Warning::Keypad(w)
    }
}

impl From<AcquisitionWarning> for Warning {
    fn from(w: AcquisitionWarning) -> Self {
        Warning::Acquisition(w)
    }
}

impl From<NetworkWarning> for Warning {
    fn from(w: NetworkWarning) -> Self {
        Warning::Network(w)
    }
}
