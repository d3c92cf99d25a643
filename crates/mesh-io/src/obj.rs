//! Wavefront OBJ: `v` and `f` lines, vertex order preserved exactly.
//!
//! Why not `tobj`: it renumbers vertices in order of first use by a face and drops unused ones,
//! whatever its options, which breaks vertex correspondence across the frames of a set and with
//! the user's own files. This reader keeps vertex i of the file as vertex i of the mesh.
//!
//! Accepted: `v x y z [w …]`; `f` with `a`, `a/b`, `a//c`, `a/b/c` forms, 1-based or negative
//! (relative) indices; triangles, and quads split along their first diagonal with a warning.
//! Everything else (`vt`, `vn`, `g`, `o`, `s`, `usemtl`, comments, …) is ignored.

use crate::Loaded;
use crate::error::{MeshIoError, Result, Warning};
use crate::mesh::{Face, Point, TriMesh};
use std::io::Write;
use std::path::Path;

/// Reads an OBJ file.
pub fn read_obj(path: &Path) -> Result<Loaded<TriMesh>> {
    let bytes = std::fs::read(path).map_err(|e| MeshIoError::io(path, e))?;
    parse_obj(&bytes, path)
}

/// Parses OBJ text; `path` only names the source in errors and warnings.
pub fn parse_obj(bytes: &[u8], path: &Path) -> Result<Loaded<TriMesh>> {
    let mut positions: Vec<Point> = Vec::with_capacity(bytes.len() / 40);
    let mut faces: Vec<Face> = Vec::with_capacity(bytes.len() / 40);
    // Line of each face, to name it when a forward index turns out to be out of range.
    let mut face_lines: Vec<u32> = Vec::with_capacity(bytes.len() / 40);
    let mut quads = 0usize;
    let err = |line: usize, message: String| MeshIoError::parse(path, line, message);

    for (line_index, line) in bytes.split(|&b| b == b'\n').enumerate() {
        let line_no = line_index + 1;
        let mut tokens = line
            .split(|b| b.is_ascii_whitespace())
            .filter(|t| !t.is_empty());
        match tokens.next() {
            Some(b"v") => {
                let mut p = [0f32; 3];
                for (k, c) in p.iter_mut().enumerate() {
                    let token = tokens.next().ok_or_else(|| {
                        err(line_no, format!("vertex has {k} coordinates, expected 3"))
                    })?;
                    *c = parse_f32(token).ok_or_else(|| {
                        err(line_no, format!("bad coordinate {:?}", lossy(token)))
                    })?;
                    if !c.is_finite() {
                        return Err(err(
                            line_no,
                            format!(
                                "vertex {} has a non-finite coordinate ({})",
                                positions.len() + 1,
                                lossy(token)
                            ),
                        ));
                    }
                }
                positions.push(p);
            }
            Some(b"f") => {
                let mut corners = [0u32; 4];
                let mut arity = 0usize;
                for token in tokens {
                    let index =
                        resolve_index(token, positions.len()).map_err(|m| err(line_no, m))?;
                    if arity < 4 {
                        corners[arity] = index;
                    }
                    arity += 1;
                }
                match arity {
                    3 => faces.push([corners[0], corners[1], corners[2]]),
                    4 => {
                        faces.push([corners[0], corners[1], corners[2]]);
                        faces.push([corners[0], corners[2], corners[3]]);
                        face_lines.push(line_no as u32);
                        quads += 1;
                    }
                    _ => {
                        return Err(MeshIoError::NonTriangleFace {
                            path: path.into(),
                            line: line_no,
                            arity,
                        });
                    }
                }
                face_lines.push(line_no as u32);
            }
            _ => {}
        }
    }

    if positions.is_empty() || faces.is_empty() {
        return Err(MeshIoError::EmptyMesh { path: path.into() });
    }
    let n = positions.len();
    if let Some(k) = faces
        .iter()
        .position(|f| f.iter().any(|&i| i as usize >= n))
    {
        let index = faces[k]
            .iter()
            .find(|&&i| i as usize >= n)
            .copied()
            .unwrap_or(0);
        return Err(MeshIoError::IndexOutOfRange {
            path: path.into(),
            line: face_lines[k] as usize,
            index: index as i64 + 1,
            vertices: n,
        });
    }
    let mut warnings = Vec::new();
    if quads > 0 {
        warnings.push(Warning {
            path: path.into(),
            message: format!("{quads} quads split into triangles"),
        });
    }
    Ok(Loaded {
        value: TriMesh { positions, faces },
        warnings,
    })
}

/// Resolves one face corner (`a`, `a/b`, `a//c`, `a/b/c`) to a 0-based vertex index. Negative
/// indices count back from the vertices read so far; positive ones are range-checked later
/// (a file may, unusually, reference a vertex defined further down).
fn resolve_index(token: &[u8], vertices_so_far: usize) -> std::result::Result<u32, String> {
    let v = token.split(|&b| b == b'/').next().unwrap_or(token);
    let i: i64 = std::str::from_utf8(v)
        .ok()
        .and_then(|s| s.parse().ok())
        .ok_or_else(|| format!("bad face index {:?}", lossy(token)))?;
    let resolved = match i {
        0 => return Err("face index 0 (OBJ indices start at 1)".into()),
        i if i > 0 => i - 1,
        i => vertices_so_far as i64 + i,
    };
    if resolved < 0 {
        return Err(format!(
            "relative face index {i} points before the first vertex ({vertices_so_far} read so far)"
        ));
    }
    u32::try_from(resolved).map_err(|_| format!("face index {i} is too large"))
}

fn parse_f32(token: &[u8]) -> Option<f32> {
    std::str::from_utf8(token).ok()?.parse().ok()
}

fn lossy(token: &[u8]) -> String {
    String::from_utf8_lossy(&token[..token.len().min(40)]).into_owned()
}

/// Writes a mesh as OBJ (`v` and `f` lines only), atomically. Coordinates are printed in their
/// shortest form that reads back to the same `f32`, so the round trip is bit-exact.
pub fn write_obj(path: &Path, mesh: &TriMesh) -> Result<()> {
    crate::atomic::write_atomic(path, |w| write_obj_to(w, mesh))
}

/// Writes OBJ text to any writer.
pub fn write_obj_to(w: &mut impl Write, mesh: &TriMesh) -> std::io::Result<()> {
    writeln!(
        w,
        "# {} vertices, {} faces (written by meshvae)",
        mesh.vertex_count(),
        mesh.face_count()
    )?;
    for p in &mesh.positions {
        writeln!(w, "v {} {} {}", p[0], p[1], p[2])?;
    }
    for f in &mesh.faces {
        writeln!(w, "f {} {} {}", f[0] + 1, f[1] + 1, f[2] + 1)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Loaded<TriMesh>> {
        parse_obj(text.as_bytes(), Path::new("t.obj"))
    }

    #[test]
    fn keeps_vertex_order_and_unused_vertices() {
        // The case tobj gets wrong: x = 1-based file index, vertex 4 unused.
        let text = "v 1 0 0\nv 2 0 0\nv 3 0 0\nv 4 0 0\nv 5 0 0\nv 6 0 0\n\
                    f 5 3 2\nf 2 6 5\nf 3 1 2\n";
        let m = parse(text).unwrap().value;
        let xs: Vec<f32> = m.positions.iter().map(|p| p[0]).collect();
        assert_eq!(xs, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        assert_eq!(m.faces, vec![[4, 2, 1], [1, 5, 4], [2, 0, 1]]);
    }

    #[test]
    fn index_forms_and_negative_indices() {
        let text = "v 0 0 0\nvt 0 0\nvn 0 0 1\nv 1 0 0\nv 0 1 0\n\
                    f 1/1 2/1/1 3//1\nf -3 -2 -1\n";
        let m = parse(text).unwrap().value;
        assert_eq!(m.faces, vec![[0, 1, 2], [0, 1, 2]]);
    }

    #[test]
    fn quads_are_split_with_a_warning() {
        let text = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n";
        let loaded = parse(text).unwrap();
        assert_eq!(loaded.value.faces, vec![[0, 1, 2], [0, 2, 3]]);
        assert_eq!(loaded.warnings.len(), 1);
        assert!(loaded.warnings[0].message.contains("1 quads"));
    }

    #[test]
    fn pentagons_are_refused() {
        let text = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 2 0\nf 1 2 3 4 5\n";
        let e = parse(text).unwrap_err();
        assert!(
            matches!(
                e,
                MeshIoError::NonTriangleFace {
                    line: 6,
                    arity: 5,
                    ..
                }
            ),
            "{e}"
        );
    }

    #[test]
    fn nan_coordinate_names_line() {
        let e = parse("v 0 0 0\nv nan 0 0\nv 1 1 1\nf 1 2 3\n").unwrap_err();
        let msg = e.to_string();
        assert!(
            msg.contains("t.obj:2:") && msg.contains("non-finite"),
            "{msg}"
        );
    }

    #[test]
    fn index_out_of_range_names_line() {
        let e = parse("v 0 0 0\nv 1 0 0\nv 1 1 1\nf 1 2 3\nf 1 2 4\n").unwrap_err();
        assert!(
            matches!(
                e,
                MeshIoError::IndexOutOfRange {
                    line: 5,
                    index: 4,
                    vertices: 3,
                    ..
                }
            ),
            "{e}"
        );
        assert!(parse("v 0 0 0\nf 1 0 1\n").is_err());
        assert!(parse("v 0 0 0\nf -1 -2 -1\n").is_err());
    }

    #[test]
    fn truncated_lines_are_parse_errors() {
        let e = parse("v 0 0 0\nv 1 0").unwrap_err();
        assert!(matches!(e, MeshIoError::Parse { line: 2, .. }), "{e}");
        let e = parse("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2").unwrap_err();
        assert!(
            matches!(
                e,
                MeshIoError::NonTriangleFace {
                    line: 4,
                    arity: 2,
                    ..
                }
            ),
            "{e}"
        );
        assert!(matches!(
            parse("").unwrap_err(),
            MeshIoError::EmptyMesh { .. }
        ));
    }

    #[test]
    fn write_then_read_is_bit_exact() {
        let mesh = TriMesh {
            positions: vec![
                [0.1, -1e-7, 3.4028235e38],
                [1.0 / 3.0, 2.5, -0.0],
                [7.0, 8.0, 9.0],
            ],
            faces: vec![[0, 1, 2], [2, 1, 0]],
        };
        let mut buf = Vec::new();
        write_obj_to(&mut buf, &mesh).unwrap();
        let back = parse_obj(&buf, Path::new("b.obj")).unwrap().value;
        assert_eq!(back.faces, mesh.faces);
        for (a, b) in back.positions.iter().zip(&mesh.positions) {
            assert_eq!(a.map(f32::to_bits), b.map(f32::to_bits));
        }
    }
}
