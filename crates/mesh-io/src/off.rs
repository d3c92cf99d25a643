//! OFF (Object File Format), ASCII: an optional `OFF` keyword, a counts line `V F E`, V vertex
//! lines `x y z` and F face lines `n i0 … i(n-1)` with 0-based indices. Vertex order is kept
//! exactly and unused vertices stay.
//!
//! Accepted: the `[ST][C][N]OFF` keyword family (`COFF`, `NOFF`, `CNOFF`, `STOFF`, …) — whatever
//! a vertex line holds after x y z (colours, normals, texture coordinates) is ignored, as are
//! colour values after a face's indices; the counts may share the keyword's line; `#` starts a
//! comment. Refused: binary OFF, and `4OFF`/`nOFF` (points of other dimensions). Faces are
//! triangles, or quads split along their first diagonal with one warning.

use crate::error::{MeshIoError, Result, Warning};
use crate::mesh::{Face, Point};
use crate::{Loaded, TriMesh};
use std::io::Write;
use std::path::Path;

/// Reads an ASCII OFF file.
pub fn read_off(path: &Path) -> Result<Loaded<TriMesh>> {
    let bytes = std::fs::read(path).map_err(|e| MeshIoError::io(path, e))?;
    parse_off(&bytes, path)
}

/// Parses OFF text; `path` only names the source in errors and warnings.
pub fn parse_off(bytes: &[u8], path: &Path) -> Result<Loaded<TriMesh>> {
    let err = |line: usize, message: String| MeshIoError::parse(path, line, message);
    let mut lines = ContentLines {
        bytes,
        pos: 0,
        line: 0,
    };

    let Some((first_no, first)) = lines.next_content() else {
        return Err(MeshIoError::EmptyMesh { path: path.into() });
    };
    let mut first_tokens = tokens(first).peekable();
    let is_keyword = first_tokens
        .peek()
        .is_some_and(|t| t.len() >= 3 && t.ends_with(b"OFF"));
    let (nv, nf) = if is_keyword {
        let keyword = first_tokens.next().unwrap_or_default();
        check_keyword(keyword).map_err(|m| err(first_no, m))?;
        if first_tokens.peek().is_some() {
            parse_counts(first_tokens).map_err(|m| err(first_no, m))?
        } else {
            let (no, line) = lines.next_content().ok_or_else(|| {
                err(
                    lines.eof_line(),
                    "unexpected end of file: missing the counts line".into(),
                )
            })?;
            parse_counts(tokens(line)).map_err(|m| err(no, m))?
        }
    } else {
        parse_counts(first_tokens).map_err(|m| err(first_no, m))?
    };
    if nv == 0 || nf == 0 {
        return Err(MeshIoError::EmptyMesh { path: path.into() });
    }

    // A vertex line takes at least 6 bytes ("0 0 0\n") and a face line 8: the claimed counts
    // can be anything, the reservations cannot exceed what the input could hold.
    let mut positions: Vec<Point> = Vec::with_capacity(nv.min(bytes.len() / 6));
    for v in 0..nv {
        let (no, line) = lines.next_content().ok_or_else(|| {
            err(
                lines.eof_line(),
                format!("unexpected end of file: {v} of {nv} vertices read"),
            )
        })?;
        let mut t = tokens(line);
        let mut p = [0f32; 3];
        for (k, c) in p.iter_mut().enumerate() {
            let token = t
                .next()
                .ok_or_else(|| err(no, format!("vertex {v} has {k} coordinates, expected 3")))?;
            *c = parse_f32(token)
                .ok_or_else(|| err(no, format!("bad coordinate {:?}", lossy(token))))?;
            if !c.is_finite() {
                return Err(err(
                    no,
                    format!("vertex {v} has a non-finite coordinate ({})", lossy(token)),
                ));
            }
        }
        positions.push(p);
    }

    let mut faces: Vec<Face> = Vec::with_capacity(nf.min(bytes.len() / 8));
    let mut quads = 0usize;
    for f in 0..nf {
        let (no, line) = lines.next_content().ok_or_else(|| {
            err(
                lines.eof_line(),
                format!("unexpected end of file: {f} of {nf} faces read"),
            )
        })?;
        let mut t = tokens(line);
        let arity_token = t.next().unwrap_or_default();
        let arity: usize = parse_str(arity_token)
            .ok_or_else(|| err(no, format!("bad face size {:?}", lossy(arity_token))))?;
        if arity != 3 && arity != 4 {
            return Err(MeshIoError::NonTriangleFace {
                path: path.into(),
                line: no,
                arity,
            });
        }
        let mut corners = [0u32; 4];
        for (k, corner) in corners.iter_mut().take(arity).enumerate() {
            let token = t
                .next()
                .ok_or_else(|| err(no, format!("face has {k} of its {arity} vertex indices")))?;
            let index = parse_i64(token)
                .ok_or_else(|| err(no, format!("bad face index {:?}", lossy(token))))?;
            *corner = u32::try_from(index)
                .ok()
                .filter(|&i| (i as usize) < nv)
                .ok_or_else(|| MeshIoError::IndexOutOfRange {
                    path: path.into(),
                    line: no,
                    index,
                    vertices: nv,
                })?;
        }
        faces.push([corners[0], corners[1], corners[2]]);
        if arity == 4 {
            faces.push([corners[0], corners[2], corners[3]]);
            quads += 1;
        }
    }

    let mut warnings = Vec::new();
    if quads > 0 {
        warnings.push(Warning {
            path: path.into(),
            message: format!("{quads} quads split into triangles"),
        });
    }
    let mut trailing = 0usize;
    while lines.next_content().is_some() {
        trailing += 1;
    }
    if trailing > 0 {
        warnings.push(Warning {
            path: path.into(),
            message: format!("{trailing} lines after the last face ignored"),
        });
    }
    Ok(Loaded {
        value: TriMesh { positions, faces },
        warnings,
    })
}

/// Lines that hold something once comments are stripped, with their 1-based numbers.
struct ContentLines<'a> {
    bytes: &'a [u8],
    pos: usize,
    /// Number of the last line consumed.
    line: usize,
}

impl<'a> ContentLines<'a> {
    fn next_content(&mut self) -> Option<(usize, &'a [u8])> {
        while self.pos < self.bytes.len() {
            let rest = &self.bytes[self.pos..];
            let end = rest.iter().position(|&b| b == b'\n').unwrap_or(rest.len());
            self.pos += end + 1;
            self.line += 1;
            let raw = &rest[..end];
            let content = &raw[..raw.iter().position(|&b| b == b'#').unwrap_or(raw.len())];
            if content.iter().any(|b| !b.is_ascii_whitespace()) {
                return Some((self.line, content));
            }
        }
        None
    }

    /// The line number to name when the data ends too early: the line after the last one.
    fn eof_line(&self) -> usize {
        self.line + 1
    }
}

fn tokens(line: &[u8]) -> impl Iterator<Item = &[u8]> {
    line.split(u8::is_ascii_whitespace)
        .filter(|t| !t.is_empty())
}

/// Accepts `OFF` with the optional `ST`, `C`, `N` prefixes; refuses what this reader would
/// misread (other dimensions) and names it.
fn check_keyword(keyword: &[u8]) -> std::result::Result<(), String> {
    let prefix = &keyword[..keyword.len().saturating_sub(3)];
    if prefix.iter().any(|&b| b == b'4' || b == b'n') {
        return Err(format!(
            "{:?}: OFF files of other dimensions are not supported",
            lossy(keyword)
        ));
    }
    if !prefix.iter().all(|b| b"STCN".contains(b)) {
        return Err(format!("unknown OFF keyword {:?}", lossy(keyword)));
    }
    Ok(())
}

fn parse_counts<'a>(
    mut t: impl Iterator<Item = &'a [u8]>,
) -> std::result::Result<(usize, usize), String> {
    let mut count = |what: &str| {
        let token = t
            .next()
            .ok_or_else(|| format!("the counts line has no {what} count"))?;
        if token.eq_ignore_ascii_case(b"BINARY") {
            return Err("binary OFF is not supported".to_string());
        }
        parse_str::<usize>(token).ok_or_else(|| format!("bad {what} count {:?}", lossy(token)))
    };
    Ok((count("vertex")?, count("face")?))
}

fn parse_str<T: std::str::FromStr>(token: &[u8]) -> Option<T> {
    std::str::from_utf8(token).ok()?.parse().ok()
}

pub(crate) fn parse_f32(token: &[u8]) -> Option<f32> {
    parse_str(token)
}

/// An integer with an optional sign, exactly as `str::parse::<i64>` accepts it, without the
/// UTF-8 check (integers are most of a face line, and this is measurably faster).
pub(crate) fn parse_i64(token: &[u8]) -> Option<i64> {
    let (negative, digits) = match token {
        [b'-', rest @ ..] => (true, rest),
        [b'+', rest @ ..] => (false, rest),
        _ => (false, token),
    };
    if digits.is_empty() {
        return None;
    }
    let mut value = 0i64;
    for &d in digits {
        if !d.is_ascii_digit() {
            return None;
        }
        let d = i64::from(d - b'0');
        value = value.checked_mul(10)?;
        value = if negative {
            value.checked_sub(d)?
        } else {
            value.checked_add(d)?
        };
    }
    Some(value)
}

/// A token for an error message: at most 40 bytes, invalid UTF-8 replaced.
pub(crate) fn lossy(token: &[u8]) -> String {
    String::from_utf8_lossy(&token[..token.len().min(40)]).into_owned()
}

/// Writes a mesh as ASCII OFF, atomically. Coordinates are printed in their shortest form that
/// reads back to the same `f32`, so the round trip is bit-exact.
pub fn write_off(path: &Path, mesh: &TriMesh) -> Result<()> {
    crate::atomic::write_atomic(path, |w| write_off_to(w, mesh))
}

/// Writes OFF text to any writer.
pub fn write_off_to(w: &mut impl Write, mesh: &TriMesh) -> std::io::Result<()> {
    writeln!(w, "OFF\n{} {} 0", mesh.vertex_count(), mesh.face_count())?;
    for p in &mesh.positions {
        writeln!(w, "{} {} {}", p[0], p[1], p[2])?;
    }
    for f in &mesh.faces {
        writeln!(w, "3 {} {} {}", f[0], f[1], f[2])?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Loaded<TriMesh>> {
        parse_off(text.as_bytes(), Path::new("t.off"))
    }

    fn awkward_mesh() -> TriMesh {
        TriMesh {
            positions: vec![
                [0.1, -1e-7, 3e38],
                [1.0 / 3.0, 2.5, -0.0],
                [7.0, f32::MIN_POSITIVE, -3.4028235e38],
                [1e-45, 0.2, 123456.79],
            ],
            faces: vec![[0, 1, 2], [2, 1, 0], [0, 2, 3]],
        }
    }

    fn assert_bit_exact(a: &TriMesh, b: &TriMesh) {
        assert_eq!(a.faces, b.faces);
        assert_eq!(a.positions.len(), b.positions.len());
        for (p, q) in a.positions.iter().zip(&b.positions) {
            assert_eq!(p.map(f32::to_bits), q.map(f32::to_bits));
        }
    }

    #[test]
    fn integer_parsing_matches_std() {
        for s in [
            "0",
            "-0",
            "+7",
            "42",
            "-42",
            "007",
            "9223372036854775807",
            "-9223372036854775808",
            "9223372036854775808",
            "-9223372036854775809",
            "",
            "-",
            "+",
            "+-1",
            "1.0",
            "1e3",
            " 1",
            "0x10",
            "\u{663}",
        ] {
            assert_eq!(parse_i64(s.as_bytes()), s.parse::<i64>().ok(), "{s:?}");
        }
    }

    #[test]
    fn write_then_read_is_bit_exact() {
        let mesh = awkward_mesh();
        let mut buf = Vec::new();
        write_off_to(&mut buf, &mesh).unwrap();
        let loaded = parse_off(&buf, Path::new("b.off")).unwrap();
        assert!(loaded.warnings.is_empty());
        assert_bit_exact(&loaded.value, &mesh);

        let dir = std::env::temp_dir().join(format!("mesh-io-off-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("m.off");
        write_off(&path, &mesh).unwrap();
        assert_bit_exact(&read_off(&path).unwrap().value, &mesh);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn coff_with_comments_colours_and_a_quad() {
        // Counts on the keyword line, colours after xyz and after face indices, comments, blank
        // lines, CRLF, an unused vertex (4), and faces in non-sorted order.
        let text = "# header comment\r\nCOFF 6 3 0 # counts here\r\n\r\n\
                    0 0 0 255 0 0 255\n1 0 0 0 255 0 255\n1 1 0 0 0 255 255\n\
                    0 1 0 1 1 1 1 # a comment\n9 9 9 0 0 0 0\n0 2 0 0 0 0 0\n\
                    3 5 3 2 0.5 0.5 0.5\n4 0 1 2 3\n  3 2 1 0\n";
        let loaded = parse(text).unwrap();
        let m = loaded.value;
        let xs: Vec<f32> = m.positions.iter().map(|p| p[1]).collect();
        assert_eq!(xs, [0.0, 0.0, 1.0, 1.0, 9.0, 2.0]);
        assert_eq!(m.faces, vec![[5, 3, 2], [0, 1, 2], [0, 2, 3], [2, 1, 0]]);
        assert_eq!(loaded.warnings.len(), 1);
        assert!(
            loaded.warnings[0].message.contains("1 quads"),
            "{:?}",
            loaded.warnings
        );
    }

    #[test]
    fn keyword_is_optional_and_noff_is_accepted() {
        let m = parse("3 1\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n").unwrap().value;
        assert_eq!(m.faces, vec![[0, 1, 2]]);
        let text = "NOFF\n3 1 0\n0 0 0 0 0 1\n1 0 0 0 0 1\n0 1 0 0 0 1\n3 0 1 2\n";
        let m = parse(text).unwrap().value;
        assert_eq!(m.positions[1], [1.0, 0.0, 0.0]);
    }

    #[test]
    fn trailing_lines_are_a_warning() {
        let loaded = parse("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 1 2\n").unwrap();
        assert_eq!(loaded.value.faces.len(), 1);
        assert!(loaded.warnings[0].message.contains("1 lines after"));
    }

    #[test]
    fn other_arities_are_refused() {
        let text = "OFF\n5 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n0 2 0\n3 0 1 2\n5 0 1 2 3 4\n";
        let e = parse(text).unwrap_err();
        assert!(
            matches!(
                e,
                MeshIoError::NonTriangleFace {
                    line: 9,
                    arity: 5,
                    ..
                }
            ),
            "{e}"
        );
        let e = parse("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n2 0 1\n").unwrap_err();
        assert!(
            matches!(
                e,
                MeshIoError::NonTriangleFace {
                    line: 6,
                    arity: 2,
                    ..
                }
            ),
            "{e}"
        );
    }

    #[test]
    fn bad_indices_name_the_line() {
        let e = parse("OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 1 3\n").unwrap_err();
        assert!(
            matches!(
                e,
                MeshIoError::IndexOutOfRange {
                    line: 7,
                    index: 3,
                    vertices: 3,
                    ..
                }
            ),
            "{e}"
        );
        let e = parse("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 -1 2\n").unwrap_err();
        assert!(
            matches!(
                e,
                MeshIoError::IndexOutOfRange {
                    line: 6,
                    index: -1,
                    ..
                }
            ),
            "{e}"
        );
        let e = parse("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1.5 2\n").unwrap_err();
        assert!(matches!(e, MeshIoError::Parse { line: 6, .. }), "{e}");
    }

    #[test]
    fn non_finite_coordinates_name_the_line() {
        for bad in ["nan", "inf", "-inf", "1e39"] {
            let text = format!("OFF\n3 1 0\n0 0 0\n1 {bad} 0\n0 1 0\n3 0 1 2\n");
            let e = parse(&text).unwrap_err();
            let msg = e.to_string();
            assert!(matches!(e, MeshIoError::Parse { line: 4, .. }), "{msg}");
            assert!(
                msg.contains("t.off:4:") && msg.contains("non-finite"),
                "{msg}"
            );
        }
    }

    #[test]
    fn truncated_files_are_parse_errors_with_line() {
        let e = parse("OFF\n3 1 0\n0 0 0\n1 0 0\n").unwrap_err();
        assert!(matches!(e, MeshIoError::Parse { line: 5, .. }), "{e}");
        let e = parse("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0").unwrap_err();
        assert!(matches!(e, MeshIoError::Parse { line: 6, .. }), "{e}");
        let e = parse("OFF\n3 1 0\n0 0 0\n1 0").unwrap_err();
        assert!(matches!(e, MeshIoError::Parse { line: 4, .. }), "{e}");
        let e = parse("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1").unwrap_err();
        assert!(matches!(e, MeshIoError::Parse { line: 6, .. }), "{e}");
        let e = parse("OFF\n").unwrap_err();
        assert!(matches!(e, MeshIoError::Parse { line: 2, .. }), "{e}");
        // A huge claimed count fails at the end of the data, without a huge allocation.
        let e = parse("OFF\n18446744073709551615 4294967295 0\n0 0 0\n").unwrap_err();
        assert!(matches!(e, MeshIoError::Parse { line: 4, .. }), "{e}");
    }

    #[test]
    fn empty_meshes_and_bad_headers() {
        for text in [
            "",
            "# only a comment\n\n",
            "OFF\n0 0 0\n",
            "OFF\n3 0 0\n0 0 0\n",
        ] {
            let e = parse(text).unwrap_err();
            assert!(matches!(e, MeshIoError::EmptyMesh { .. }), "{text:?}: {e}");
        }
        let e = parse("OFF\n3 x 0\n").unwrap_err();
        assert!(matches!(e, MeshIoError::Parse { line: 2, .. }), "{e}");
        let e = parse("OFF\n3\n").unwrap_err();
        assert!(matches!(e, MeshIoError::Parse { line: 2, .. }), "{e}");
        let e = parse("OFF BINARY\n3 1 0\n").unwrap_err();
        assert!(e.to_string().contains("binary OFF"), "{e}");
        let e = parse("4OFF\n3 1 0\n").unwrap_err();
        assert!(matches!(e, MeshIoError::Parse { line: 1, .. }), "{e}");
        let e = parse("XOFF\n3 1 0\n").unwrap_err();
        assert!(matches!(e, MeshIoError::Parse { line: 1, .. }), "{e}");
    }
}
