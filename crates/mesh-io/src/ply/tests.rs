use super::*;

fn parse(bytes: &[u8]) -> Result<Loaded<TriMesh>> {
    parse_ply(bytes, Path::new("t.ply"))
}

const ENCODINGS: [PlyEncoding; 3] = [
    PlyEncoding::Ascii,
    PlyEncoding::BinaryLittleEndian,
    PlyEncoding::BinaryBigEndian,
];

fn awkward_mesh() -> TriMesh {
    TriMesh {
        positions: vec![
            [0.1, -1e-7, 3e38],
            [1.0 / 3.0, 2.5, -0.0],
            [7.0, f32::MIN_POSITIVE, -3.4028235e38],
            [1e-45, 0.2, 123456.79],
            [-1.0, 0.0, 1e-7],
        ],
        faces: vec![[0, 1, 2], [2, 1, 0], [0, 2, 3]],
    }
}

fn assert_bit_exact(a: &TriMesh, b: &TriMesh) {
    assert_eq!(a.faces, b.faces);
    assert_eq!(a.positions.len(), b.positions.len());
    for (p, q) in a.positions.iter().zip(&b.positions) {
        assert_eq!(p.map(f32::to_bits), q.map(f32::to_bits), "{p:?} vs {q:?}");
    }
}

#[test]
fn write_then_read_is_bit_exact_in_every_encoding() {
    let mesh = awkward_mesh();
    let dir = std::env::temp_dir().join(format!("mesh-io-ply-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for encoding in ENCODINGS {
        let mut buf = Vec::new();
        write_ply_to(&mut buf, &mesh, encoding).unwrap();
        let loaded = parse(&buf).unwrap();
        assert!(
            loaded.warnings.is_empty(),
            "{encoding:?}: {:?}",
            loaded.warnings
        );
        assert_bit_exact(&loaded.value, &mesh);

        let path = dir.join(format!("{encoding:?}.ply"));
        write_ply(&path, &mesh, encoding).unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), buf);
        assert_bit_exact(&read_ply(&path).unwrap().value, &mesh);
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn binary_layout_is_as_declared() {
    let mesh = TriMesh {
        positions: vec![[1.0, 2.0, 3.0]],
        faces: vec![[0, 0, 0]],
    };
    let mut buf = Vec::new();
    write_ply_to(&mut buf, &mesh, PlyEncoding::BinaryBigEndian).unwrap();
    let data = &buf[buf.len() - 25..];
    assert_eq!(&data[..4], &1f32.to_be_bytes());
    assert_eq!(&data[8..12], &3f32.to_be_bytes());
    assert_eq!(data[12], 3);
    assert_eq!(&data[13..17], &[0, 0, 0, 0]);
    assert!(buf[..buf.len() - 25].ends_with(b"end_header\n"));
}

#[test]
fn writer_refuses_indices_beyond_int() {
    let mesh = TriMesh {
        positions: vec![[0.0; 3]],
        faces: vec![[0, 0, 1 << 31]],
    };
    let e = write_ply_to(&mut Vec::new(), &mesh, PlyEncoding::Ascii).unwrap_err();
    assert_eq!(e.kind(), std::io::ErrorKind::InvalidInput);
}

/// Extra vertex properties (normals, colours), a skipped element with a list before the faces,
/// extra face properties around the index list, a quad, an unused vertex, and a trailing
/// element.
const RICH_ASCII: &str = "ply\r\n\
format ascii 1.0\n\
comment made by hand\n\
obj_info nothing to see\n\
element vertex 6\n\
property float x\n\
property float y\n\
property float z\n\
property float nx\n\
property float ny\n\
property float nz\n\
property uchar red\n\
property uchar green\n\
property uchar blue\n\
element material 2\n\
property list uchar float params\n\
property int id\n\
element face 3\n\
property uchar flags\n\
property list uchar int vertex_indices\n\
property list uint8 float texcoord\n\
element edge 2\n\
property int vertex1\n\
property int vertex2\n\
end_header\n\
0 0 0 0 0 1 255 0 0\n\
1 0 0 0 0 1 0 255 0\n\
1 1 0 0 0 1 0 0 255\n\
0 1 0 0 0 1 9 9 9\n\
7 7 7 0 0 1 1 1 1\n\
5 5 5 0 0 1 1 1 1\n\
3 0.1 0.2 0.3 7\n\
0 8\n\
0 4 0 1 2 3 0\n\
1 3 2 1 0 6 0 0 1 0 1 1\n\
2 3 0 5 3\n\
2 0.5 0.5\n\
0 1\n\
1 2\n";

#[test]
fn ascii_with_extra_properties_elements_and_a_quad() {
    let loaded = parse(RICH_ASCII.as_bytes()).unwrap();
    let m = &loaded.value;
    let xs: Vec<f32> = m.positions.iter().map(|p| p[0]).collect();
    assert_eq!(xs, [0.0, 1.0, 1.0, 0.0, 7.0, 5.0]);
    assert_eq!(m.positions[5], [5.0, 5.0, 5.0]);
    assert_eq!(m.faces, vec![[0, 1, 2], [0, 2, 3], [2, 1, 0], [0, 5, 3]]);
    assert_eq!(loaded.warnings.len(), 1, "{:?}", loaded.warnings);
    assert!(loaded.warnings[0].message.contains("1 quads"));
}

/// Little/big-endian byte builder for hand-made binary files.
struct Bytes {
    big_endian: bool,
    data: Vec<u8>,
}

macro_rules! push_fns {
    ($($name:ident: $t:ty),*) => {
        $(fn $name(&mut self, v: $t) -> &mut Self {
            let b = if self.big_endian { v.to_be_bytes() } else { v.to_le_bytes() };
            self.data.extend_from_slice(&b);
            self
        })*
    };
}

impl Bytes {
    push_fns!(i8: i8, u8: u8, i16: i16, u16: u16, i32: i32, u32: u32, f32: f32, f64: f64);
}

/// Mixed scalar types for x y z, a list inside the vertex element, `vertex_index` with
/// ushort/uint types, a property after it, and a trailing element with a list.
fn mixed_binary(big_endian: bool) -> Vec<u8> {
    let format = if big_endian {
        "binary_big_endian"
    } else {
        "binary_little_endian"
    };
    let header = format!(
        "ply\nformat {format} 1.0\n\
         element vertex 3\n\
         property double x\nproperty int16 y\nproperty uchar red\nproperty float z\n\
         property list uchar int extra\n\
         element face 2\n\
         property list uint16 uint32 vertex_index\nproperty char flag\n\
         element edge 1\n\
         property list int short pair\n\
         end_header\n"
    );
    let mut b = Bytes {
        big_endian,
        data: header.into_bytes(),
    };
    b.f64(0.5).i16(-2).u8(7).f32(1.25).u8(2).i32(1).i32(2);
    b.f64(-0.0).i16(300).u8(7).f32(1e-7).u8(0);
    b.f64(3.0).i16(0).u8(7).f32(-4.5).u8(1).i32(9);
    b.u16(3).u32(0).u32(1).u32(2).i8(-1);
    b.u16(3).u32(2).u32(1).u32(0).i8(5);
    b.i32(2).i16(0).i16(1);
    b.data
}

#[test]
fn hand_built_binary_in_both_byte_orders() {
    for big_endian in [true, false] {
        let loaded = parse(&mixed_binary(big_endian)).unwrap();
        assert!(loaded.warnings.is_empty(), "{:?}", loaded.warnings);
        let m = loaded.value;
        let expected = [[0.5, -2.0, 1.25], [-0.0, 300.0, 1e-7], [3.0, 0.0, -4.5]];
        for (p, q) in m.positions.iter().zip(&expected) {
            assert_eq!(p.map(f32::to_bits), q.map(f32::to_bits));
        }
        assert_eq!(m.positions.len(), 3);
        assert_eq!(m.faces, vec![[0, 1, 2], [2, 1, 0]]);
    }
    // The same bytes read in the other byte order are garbage, not the same mesh.
    let mut swapped = mixed_binary(true);
    let at = swapped.windows(3).position(|w| w == b"big").unwrap();
    swapped.splice(at..at + 3, *b"little");
    assert!(
        parse(&swapped)
            .map(|l| l.value.positions[0][0] != 0.5)
            .unwrap_or(true)
    );
}

#[test]
fn trailing_bytes_are_a_warning() {
    let mut bytes = mixed_binary(false);
    bytes.extend_from_slice(&[1, 2]);
    let loaded = parse(&bytes).unwrap();
    assert!(
        loaded.warnings[0].message.contains("2 bytes"),
        "{:?}",
        loaded.warnings
    );
}

fn ascii_tri(vertices: &str, faces: &str, nv: usize, nf: usize) -> String {
    format!(
        "ply\nformat ascii 1.0\nelement vertex {nv}\nproperty float x\nproperty float y\n\
         property float z\nelement face {nf}\nproperty list uchar int vertex_indices\n\
         end_header\n{vertices}{faces}"
    )
}

const TRI: &str = "0 0 0\n1 0 0\n0 1 0\n";

#[test]
fn face_errors_name_the_line() {
    // Data starts on line 10.
    let e = parse(ascii_tri(TRI, "3 0 1 2\n5 0 1 2 0 1\n", 3, 2).as_bytes()).unwrap_err();
    assert!(
        matches!(
            e,
            MeshIoError::NonTriangleFace {
                line: 14,
                arity: 5,
                ..
            }
        ),
        "{e}"
    );
    let e = parse(ascii_tri(TRI, "2 0 1\n", 3, 1).as_bytes()).unwrap_err();
    assert!(
        matches!(
            e,
            MeshIoError::NonTriangleFace {
                line: 13,
                arity: 2,
                ..
            }
        ),
        "{e}"
    );
    let e = parse(ascii_tri(TRI, "3 0 1 2\n3 0\n1 3\n", 3, 2).as_bytes()).unwrap_err();
    let expected = MeshIoError::IndexOutOfRange {
        path: "t.ply".into(),
        line: 15,
        index: 3,
        vertices: 3,
    };
    assert_eq!(e.to_string(), expected.to_string());
    let e = parse(ascii_tri(TRI, "3 0 -1 2\n", 3, 1).as_bytes()).unwrap_err();
    assert!(
        matches!(
            e,
            MeshIoError::IndexOutOfRange {
                line: 13,
                index: -1,
                ..
            }
        ),
        "{e}"
    );
    let e = parse(ascii_tri(TRI, "3 0 1.0 2\n", 3, 1).as_bytes()).unwrap_err();
    assert!(matches!(e, MeshIoError::Parse { line: 13, .. }), "{e}");
    // A list count outside its declared type.
    let e = parse(ascii_tri(TRI, "259 0 1 2\n", 3, 1).as_bytes()).unwrap_err();
    assert!(matches!(e, MeshIoError::Parse { line: 13, .. }), "{e}");

    // Binary: the same checks, line 0.
    let mut b = Bytes {
        big_endian: false,
        data: Vec::new(),
    };
    let mesh = TriMesh {
        positions: vec![[0.0; 3]; 3],
        faces: vec![[0, 1, 2]],
    };
    write_ply_to(&mut b.data, &mesh, PlyEncoding::BinaryLittleEndian).unwrap();
    let n = b.data.len();
    b.data[n - 4..].copy_from_slice(&7i32.to_le_bytes());
    let e = parse(&b.data).unwrap_err();
    assert!(
        matches!(
            e,
            MeshIoError::IndexOutOfRange {
                line: 0,
                index: 7,
                ..
            }
        ),
        "{e}"
    );
    b.data[n - 13] = 6;
    let e = parse(&b.data).unwrap_err();
    assert!(
        matches!(
            e,
            MeshIoError::NonTriangleFace {
                line: 0,
                arity: 6,
                ..
            }
        ),
        "{e}"
    );
}

#[test]
fn non_finite_coordinates() {
    for bad in ["nan", "inf", "1e39"] {
        let e =
            parse(ascii_tri(&format!("0 0 0\n1 {bad} 0\n0 1 0\n"), "3 0 1 2\n", 3, 1).as_bytes())
                .unwrap_err();
        let msg = e.to_string();
        assert!(matches!(e, MeshIoError::Parse { line: 11, .. }), "{msg}");
        assert!(
            msg.contains("t.ply:11:") && msg.contains("non-finite"),
            "{msg}"
        );
    }
    // A finite double beyond f32's range is non-finite once converted.
    let text = "ply\nformat ascii 1.0\nelement vertex 1\nproperty double x\nproperty double y\n\
                property double z\nelement face 1\nproperty list uchar int vertex_indices\n\
                end_header\n0 1e300 0\n3 0 0 0\n";
    let e = parse(text.as_bytes()).unwrap_err();
    assert!(matches!(e, MeshIoError::Parse { line: 10, .. }), "{e}");

    let mesh = TriMesh {
        positions: vec![[0.0; 3], [1.0, f32::NAN, 0.0], [0.0; 3]],
        faces: vec![[0, 1, 2]],
    };
    for encoding in [
        PlyEncoding::BinaryLittleEndian,
        PlyEncoding::BinaryBigEndian,
    ] {
        let mut buf = Vec::new();
        write_ply_to(&mut buf, &mesh, encoding).unwrap();
        let e = parse(&buf).unwrap_err();
        assert!(matches!(e, MeshIoError::NonFinite { vertex: 1, .. }), "{e}");
    }
}

#[test]
fn truncated_data_is_a_parse_error() {
    let e = parse(ascii_tri("0 0 0\n1 0 0\n0 1", "", 3, 1).as_bytes()).unwrap_err();
    assert!(matches!(e, MeshIoError::Parse { line: 12, .. }), "{e}");
    let e = parse(ascii_tri(TRI, "3 0 1 2\n", 3, 2).as_bytes()).unwrap_err();
    assert!(matches!(e, MeshIoError::Parse { line: 14, .. }), "{e}");
    assert!(e.to_string().contains("face 1"), "{e}");
    let full = mixed_binary(true);
    for cut in [full.len() - 1, full.len() - 9, full.len() - 40] {
        let e = parse(&full[..cut]).unwrap_err();
        assert!(matches!(e, MeshIoError::Parse { line: 0, .. }), "{e}");
        assert!(e.to_string().contains("end of file"), "{e}");
    }
    // Counts far beyond the data fail at its end (and reserve nothing in proportion to them).
    for counts in [
        (4294967295usize, 1usize),
        (3, 4294967295),
        (usize::MAX, usize::MAX),
    ] {
        let text = ascii_tri(TRI, "3 0 1 2\n", counts.0, counts.1);
        assert!(matches!(
            parse(text.as_bytes()),
            Err(MeshIoError::Parse { .. })
        ));
        let text = text.replace("ascii", "binary_little_endian");
        assert!(matches!(
            parse(text.as_bytes()),
            Err(MeshIoError::Parse { .. })
        ));
    }
}

#[test]
fn empty_meshes() {
    for (nv, nf) in [(0, 1), (3, 0)] {
        let e = parse(ascii_tri("", "", nv, nf).as_bytes()).unwrap_err();
        assert!(matches!(e, MeshIoError::EmptyMesh { .. }), "{e}");
    }
    let points_only = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n\
                       property float y\nproperty float z\nend_header\n0 0 0\n";
    let e = parse(points_only.as_bytes()).unwrap_err();
    assert!(matches!(e, MeshIoError::EmptyMesh { .. }), "{e}");
}

#[test]
fn header_errors_name_the_line() {
    let valid = ascii_tri(TRI, "3 0 1 2\n", 3, 1);
    assert!(parse(valid.as_bytes()).is_ok());
    let cases: &[(&str, &str, usize)] = &[
        ("ply\n", "plx\n", 1),
        ("format ascii 1.0", "format ebcdic 1.0", 2),
        ("format ascii 1.0", "format ascii 2.0", 2),
        ("property float y", "property float16 y", 5),
        ("property float y", "property float x", 5),
        ("property float z\n", "", 3),
        ("element vertex 3", "element vertex -3", 3),
        ("element vertex 3", "element vertex", 3),
        (
            "list uchar int vertex_indices",
            "list uchar float vertex_indices",
            8,
        ),
        (
            "list uchar int vertex_indices",
            "list float int vertex_indices",
            8,
        ),
        ("list uchar int vertex_indices", "list uchar int corners", 7),
        (
            "end_header\n",
            "element vertex 1\nproperty float x\nend_header\n",
            9,
        ),
        ("end_header\n", "end_header now\n", 9),
        ("end_header\n", "bogus line\nend_header\n", 9),
    ];
    for &(from, to, line) in cases {
        let text = valid.replacen(from, to, 1);
        let e = parse(text.as_bytes()).unwrap_err();
        assert!(
            matches!(e, MeshIoError::Parse { line: l, .. } if l == line),
            "{from:?} -> {to:?}: {e}"
        );
    }
    let e = parse(b"ply\nformat ascii 1.0\nproperty float x\nend_header\n").unwrap_err();
    assert!(matches!(e, MeshIoError::Parse { line: 3, .. }), "{e}");
    let e = parse(b"ply\nelement vertex 1\nproperty float x\n").unwrap_err();
    assert!(matches!(e, MeshIoError::Parse { line: 3, .. }), "{e}");
    let e = parse(b"ply\nelement vertex 1\nend_header\n").unwrap_err();
    assert!(e.to_string().contains("no format line"), "{e}");
    let e = parse(b"").unwrap_err();
    assert!(matches!(e, MeshIoError::Parse { line: 1, .. }), "{e}");
}
