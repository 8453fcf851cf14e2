//! The output mesh: degenerate triangles dropped (reported), vertex normals from the faces.

use super::super::SurfaceProblem;
use super::assembly::Assembly;
use super::SurfaceError;
use crate::sparse_llt::SolveError;
use nalgebra::Vector3;

/// `#F` triangles and `#V` unit vertex normals.
pub(super) type TrianglesAndNormals = (Vec<[u32; 3]>, Vec<Vector3<f64>>);

/// The output mesh: triangles that came out degenerate in 3D are dropped (reported; the
/// threshold, a millionth of a target triangle, keeps them non-degenerate once written in
/// f32), vertex normals from the faces (the propagated normal where they cancel). An error
/// when a vertex is not finite.
pub(super) fn output(
    asm: &Assembly,
    nstar: &[Vector3<f64>],
    edge: f64,
    problems: &mut Vec<SurfaceProblem>,
) -> Result<TrianglesAndNormals, SurfaceError> {
    let scale = edge * edge;
    let nv = asm.positions.len();
    let mut triangles = Vec::with_capacity(asm.triangles.len());
    let mut vn = vec![Vector3::zeros(); nv];
    let mut degenerate = 0;
    for t in &asm.triangles {
        let [a, b, cc] = t.map(|i| asm.positions[i]);
        let fnrm = (b - a).cross(&(cc - a));
        // Degenerate once written in f32 (the glTF's coordinates) is degenerate too: a sliver
        // between two curves that retrace each other can have an area in f64 and none in f32.
        let [a32, b32, c32] = [a, b, cc].map(|p| p.map(|x| x as f32 as f64));
        if fnrm.norm().is_nan()
            || fnrm.norm() <= 1e-12 * scale
            || !fnrm.iter().all(|x| x.is_finite())
            || (b32 - a32).cross(&(c32 - a32)).norm() <= 0.0
        {
            degenerate += 1;
            continue;
        }
        for &i in t {
            vn[i] += fnrm;
        }
        triangles.push(t.map(|i| i as u32));
    }
    if degenerate > 0 {
        problems.push(SurfaceProblem::ZeroArea {
            triangles: degenerate,
        });
    }
    let normals: Vec<Vector3<f64>> = vn
        .iter()
        .zip(nstar)
        .map(|(v, s)| v.try_normalize(1e-300).unwrap_or(*s))
        .collect();
    if let Some(i) = asm
        .positions
        .iter()
        .position(|p| !p.iter().all(|x| x.is_finite()))
    {
        return Err(SurfaceError::Solve(SolveError::Faer(format!(
            "vertex {i} is not finite"
        ))));
    }
    Ok((triangles, normals))
}
