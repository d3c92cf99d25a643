//! Thousands of mutated OFF and PLY files (ASCII, binary little- and big-endian): every parse
//! returns a valid mesh or an error, never a panic, and a header claiming huge counts never
//! makes a reader allocate in proportion to the claim.

mod common;
use common::Rng;

use mesh_io::off::{parse_off, write_off_to};
use mesh_io::ply::{PlyEncoding, parse_ply, write_ply_to};
use mesh_io::{Loaded, Result, TriMesh};
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::path::Path;

/// The system allocator, recording the largest single request made by the current thread
/// (per thread, so tests running in parallel do not see each other's allocations).
struct LargestAllocation;

thread_local! {
    static LARGEST: Cell<usize> = const { Cell::new(0) };
}

fn note(size: usize) {
    let _ = LARGEST.try_with(|l| l.set(l.get().max(size)));
}

// SAFETY: every call is forwarded unchanged to the system allocator; `note` does not allocate.
unsafe impl GlobalAlloc for LargestAllocation {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note(layout.size());
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note(layout.size());
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note(new_size);
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOCATOR: LargestAllocation = LargestAllocation;

type Reader = fn(&[u8], &Path) -> Result<Loaded<TriMesh>>;

/// One format under test: its name, reader, and a valid file written by its writer.
struct Case {
    name: &'static str,
    read: Reader,
    file: Vec<u8>,
}

fn cases(mesh: &TriMesh) -> Vec<Case> {
    let mut off = Vec::new();
    write_off_to(&mut off, mesh).unwrap();
    let mut cases = vec![Case {
        name: "off",
        read: parse_off,
        file: off,
    }];
    for (name, encoding) in [
        ("ply-ascii", PlyEncoding::Ascii),
        ("ply-le", PlyEncoding::BinaryLittleEndian),
        ("ply-be", PlyEncoding::BinaryBigEndian),
    ] {
        let mut file = Vec::new();
        write_ply_to(&mut file, mesh, encoding).unwrap();
        cases.push(Case {
            name,
            read: parse_ply,
            file,
        });
    }
    cases
}

/// A 7×7 grid with awkward coordinates and one unused vertex: 50 vertices, 72 triangles.
fn grid_mesh() -> TriMesh {
    let n = 7;
    let mut positions: Vec<[f32; 3]> = (0..n * n)
        .map(|i| {
            let (x, y) = ((i % n) as f32, (i / n) as f32);
            [x * 0.1, y / 3.0, ((i * 7) % 5) as f32 * -1e-7]
        })
        .collect();
    positions.push([3e38, -0.0, 1e-45]);
    let mut faces = Vec::new();
    for y in 0..n - 1 {
        for x in 0..n - 1 {
            let i = (y * n + x) as u32;
            let n = n as u32;
            faces.push([i, i + 1, i + n + 1]);
            faces.push([i, i + n + 1, i + n]);
        }
    }
    TriMesh { positions, faces }
}

fn tiny_mesh() -> TriMesh {
    TriMesh {
        positions: vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.5],
            [0.25, 0.5, 1.0],
        ],
        faces: vec![[0, 1, 2], [0, 3, 1]],
    }
}

/// Parses `bytes`; a mesh that comes back must be valid. Returns whether it parsed.
fn check(case: &Case, bytes: &[u8]) -> bool {
    let path = Path::new(case.name);
    match (case.read)(bytes, path) {
        Ok(loaded) => {
            if let Err(e) = loaded.value.validate(path) {
                panic!("{}: the reader returned an invalid mesh: {e}", case.name);
            }
            true
        }
        Err(_) => false,
    }
}

const TOKENS: &[&[u8]] = &[
    b"nan",
    b"inf",
    b"-",
    b"-1",
    b"0",
    b"4294967295",
    b"1e39",
    b"\n",
    b" ",
    b"\r\n",
    b"#",
    b"\xff\xff\xff\xff",
    b"\0\0",
    b"OFF",
    b"5 0 1 2 3 4\n",
    b"4 0 1 2 3\n",
    b"end_header\n",
    b"element vertex 3\n",
    b"element edge 4294967295\n",
    b"property list uint uint vertex_indices\n",
    b"property float z\n",
    b"property list int double q\n",
    b"comment x\n",
];

fn mutate(bytes: &mut Vec<u8>, rng: &mut Rng) {
    for _ in 0..1 + rng.below(4) {
        if bytes.is_empty() {
            return;
        }
        let at = rng.below(bytes.len());
        match rng.below(8) {
            0 => bytes[at] ^= 1 << rng.below(8),
            1 => bytes[at] = rng.next() as u8,
            2 => {
                let n = 1 + rng.below(8);
                let random: Vec<u8> = (0..n).map(|_| rng.next() as u8).collect();
                bytes.splice(at..at, random);
            }
            3 => {
                let end = (at + 1 + rng.below(16)).min(bytes.len());
                bytes.drain(at..end);
            }
            4 => bytes.truncate(at),
            5 => {
                // The next digit from `at` on becomes another digit.
                if let Some(k) = bytes[at..].iter().position(u8::is_ascii_digit) {
                    bytes[at + k] = b'0' + rng.below(10) as u8;
                }
            }
            6 => {
                let token = TOKENS[rng.below(TOKENS.len())];
                bytes.splice(at..at, token.iter().copied());
            }
            _ => {
                let end = (at + 1 + rng.below(32)).min(bytes.len());
                let chunk = bytes[at..end].to_vec();
                let to = rng.below(bytes.len());
                bytes.splice(to..to, chunk);
            }
        }
    }
}

#[test]
fn valid_files_read_back_exactly() {
    let mesh = grid_mesh();
    for case in cases(&mesh) {
        let loaded = (case.read)(&case.file, Path::new(case.name)).unwrap();
        assert!(loaded.warnings.is_empty(), "{}", case.name);
        assert_eq!(loaded.value.faces, mesh.faces, "{}", case.name);
        let bits = |m: &TriMesh| -> Vec<[u32; 3]> {
            m.positions.iter().map(|p| p.map(f32::to_bits)).collect()
        };
        assert_eq!(bits(&loaded.value), bits(&mesh), "{}", case.name);
    }
}

#[test]
fn every_truncation_is_an_error_or_a_valid_mesh() {
    for case in cases(&tiny_mesh()) {
        assert!(check(&case, &case.file));
        for cut in 0..case.file.len() {
            check(&case, &case.file[..cut]);
        }
    }
    let mut rng = Rng(0x2545_F491_4F6C_DD1D);
    for case in cases(&grid_mesh()) {
        for _ in 0..300 {
            let cut = rng.below(case.file.len());
            check(&case, &case.file[..cut]);
        }
    }
}

#[test]
fn mutated_files_never_panic() {
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    for case in cases(&grid_mesh()) {
        let (mut ok, mut failed) = (0, 0);
        for _ in 0..5000 {
            let mut bytes = case.file.clone();
            mutate(&mut bytes, &mut rng);
            if check(&case, &bytes) {
                ok += 1;
            } else {
                failed += 1;
            }
        }
        // Both outcomes occur, or the mutations are not reaching the parser's paths.
        assert!(
            ok > 0 && failed > 0,
            "{}: {ok} parsed, {failed} refused",
            case.name
        );
    }
}

const COUNTS: &[&str] = &[
    "0",
    "1",
    "2",
    "49",
    "51",
    "71",
    "73",
    "4294967295",
    "4294967296",
    "18446744073709551615",
    "18446744073709551616",
    "-1",
    "1e3",
];

/// Index of the first line of `file` starting with `prefix`.
fn line_of(file: &[u8], prefix: &[u8]) -> usize {
    file.split(|&b| b == b'\n')
        .position(|line| line.starts_with(prefix))
        .expect("the writer's header has this line")
}

/// Replaces the `which`-th space-separated token of line `line` (0-based) by `value`.
fn replace_token(file: &[u8], line: usize, which: usize, value: &str) -> Vec<u8> {
    let mut lines: Vec<Vec<u8>> = file.split(|&b| b == b'\n').map(<[u8]>::to_vec).collect();
    let mut tokens: Vec<&[u8]> = lines[line].split(|&b| b == b' ').collect();
    tokens[which] = value.as_bytes();
    lines[line] = tokens.join(&b' ');
    lines.join(&b'\n')
}

/// Byte offset just after the first occurrence of `needle`.
fn line_end(file: &[u8], needle: &[u8]) -> usize {
    let at = file.windows(needle.len()).position(|w| w == needle);
    at.expect("the writer's header has this line") + needle.len()
}

/// Largest single allocation made by `f` on this thread.
fn largest_allocation(f: impl FnOnce()) -> usize {
    LARGEST.with(|l| l.set(0));
    f();
    LARGEST.with(Cell::get)
}

#[test]
fn altered_header_counts_are_handled_without_huge_allocations() {
    // The instrument works: a 1 MiB buffer is seen.
    let seen = largest_allocation(|| drop(std::hint::black_box(Vec::<u8>::with_capacity(1 << 20))));
    assert!(seen >= 1 << 20, "{seen}");
    let mesh = grid_mesh();
    for case in cases(&mesh) {
        // (line, token index) of the vertex count and of the face count.
        let (vertices, faces) = if case.name == "off" {
            ((1, 0), (1, 1))
        } else {
            let file = &case.file;
            (
                (line_of(file, b"element vertex"), 2),
                (line_of(file, b"element face"), 2),
            )
        };
        let mut variants = Vec::new();
        for count in COUNTS {
            let one = replace_token(&case.file, vertices.0, vertices.1, count);
            variants.push(replace_token(&one, faces.0, faces.1, count));
            variants.push(one);
            variants.push(replace_token(&case.file, faces.0, faces.1, count));
        }
        if case.name != "off" {
            for (from, to) in [
                ("property float x", "property double x"),
                ("property float z", "property uchar z"),
                ("list uchar int", "list int int"),
                ("list uchar int", "list uchar uint8"),
                ("list uchar int", "list uint uint"),
                ("vertex_indices", "colour"),
            ] {
                let header_end = line_end(&case.file, b"end_header\n");
                let header = std::str::from_utf8(&case.file[..header_end]).unwrap();
                let mut bytes = header.replacen(from, to, 1).into_bytes();
                bytes.extend_from_slice(&case.file[header_end..]);
                variants.push(bytes);
            }
        }
        for bytes in &variants {
            let largest = largest_allocation(|| {
                check(&case, bytes);
            });
            let bound = 16 * bytes.len() + (64 << 10);
            assert!(
                largest <= bound,
                "{}: a {}-byte file made a {largest}-byte allocation",
                case.name,
                bytes.len()
            );
        }
        // The huge claims are refused, not read as something else.
        for huge in ["4294967295", "18446744073709551615"] {
            let bytes = replace_token(&case.file, vertices.0, vertices.1, huge);
            assert!(
                (case.read)(&bytes, Path::new(case.name)).is_err(),
                "{}",
                case.name
            );
        }
    }
}

/// Read speed on a real mesh (elephant-gallop frame 1: 42321 vertices, 84638 faces), best of
/// 30 runs; measurement only, run with `--release -- --ignored --nocapture`. Asserts that every
/// format reads back the same mesh.
#[test]
#[ignore]
fn read_speed_on_elephant() {
    let Some(dir) = mesh_io::datasets::find_or_skip("elephant-gallop") else {
        return;
    };
    let obj = std::fs::read(dir.join("1.obj")).unwrap();
    let mesh = mesh_io::obj::parse_obj(&obj, Path::new("1.obj"))
        .unwrap()
        .value;
    let time = |name: &str, bytes: &[u8], read: Reader| {
        let mut best = f64::MAX;
        for _ in 0..30 {
            let start = std::time::Instant::now();
            let loaded = std::hint::black_box(read(bytes, Path::new(name)).unwrap());
            best = best.min(start.elapsed().as_secs_f64());
            assert_eq!(loaded.value, mesh, "{name}");
        }
        let mb = bytes.len() as f64 / 1e6;
        println!(
            "{name}: {mb:.2} MB, {:.1} ms, {:.0} MB/s",
            best * 1e3,
            mb / best
        );
    };
    time("obj", &obj, mesh_io::obj::parse_obj);
    for case in cases(&mesh) {
        time(case.name, &case.file, case.read);
    }
}
