//! Issue 34: nodes joined after the fact. A crossing tagged on one of its curves only is
//! joined to the other curve where it passes, at the arc length where it was.

use sfs::simulate::{self, scene};
use sfs_geometry::network::join::{apply_joins, find_joins, JoinParams};
use sfs_geometry::network::{NetworkParams, Reconstructor};

/// Joins on exact frames (no noise) place each node at the true arc length within 1 mm, and
/// nothing else is joined: over the shipped scenes with crossings that can be left out, a
/// third of them removed from the exact scan (one pass: what stays connected).
#[test]
fn issue_34_joins_on_exact_frames_find_the_true_arc_length() {
    for name in ["sphere-octa", "torus", "bowl", "cone", "relief"] {
        let s = scene::builtin(name).expect("shipped scene");
        for fraction in [1.0 / 3.0] {
            let left_out = simulate::untagged_crossings(&s, fraction, 1);
            assert!(!left_out.is_empty(), "{name}: no crossing to leave out");
            let mut scan = s.exact_scan();
            // The tags removed, with their true distance along their curve.
            let mut removed = Vec::new();
            for &(ci, k) in left_out.iter().rev() {
                let tag = scan.curves[ci].tags.remove(k);
                let lengths = &mut scan.curves[ci].segment_lengths;
                lengths.remove(k.min(lengths.len() - 1));
                removed.push((tag.node, scan.curves[ci].index, tag.d));
            }
            let net = Reconstructor::new()
                .run(&scan.curves, &NetworkParams::default())
                .unwrap_or_else(|e| panic!("{name}: {e}"));
            let joins = find_joins(&net.positions, &JoinParams::default());
            assert_eq!(
                joins.len(),
                removed.len(),
                "{name} ({fraction:.2}): joins {joins:?} for {removed:?}"
            );
            for (node, curve, d) in &removed {
                let j = joins
                    .iter()
                    .find(|j| j.node == *node)
                    .unwrap_or_else(|| panic!("{name}: node {node} not joined: {joins:?}"));
                assert_eq!(j.curve, *curve, "{name}: node {node}");
                assert!(
                    (j.d - d).abs() < 1e-3,
                    "{name}: node {node} joined at {:.4} m, tagged at {d:.4} m",
                    j.d
                );
            }
            // Put back, the scan has its tags where they were.
            let mut joined = scan.curves.clone();
            assert_eq!(apply_joins(&mut joined, &joins), removed.len());
            let original = s.exact_scan();
            for (a, b) in joined.iter().zip(&original.curves) {
                assert_eq!(a.nodes(), b.nodes(), "{name}: curve {}", a.index);
            }
        }
    }
}
