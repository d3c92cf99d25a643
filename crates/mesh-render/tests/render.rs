//! The rasterizer against analytic expectations: areas, framing, orientation, depth, shading.

mod common;

use common::*;
use mesh_render::{Bounds, MARGIN, RenderOptions, View, render};

fn options(width: u32, height: u32, view: View) -> RenderOptions {
    RenderOptions {
        width,
        height,
        view,
        ..Default::default()
    }
}

#[test]
fn a_triangle_covers_its_projected_area() {
    // Frame the unit square: 400 px minus 5% margins = 360 px per unit.
    let frame = Bounds {
        min: [0.0, 0.0, 0.0],
        max: [1.0, 1.0, 0.0],
    };
    let positions = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.3, 0.8, 0.0]];
    let o = RenderOptions {
        frame: Some(frame),
        ..options(400, 400, View::Front)
    };
    let image = render(&positions, &[[0, 1, 2]], None, &o).unwrap();
    let scale = 400.0 * (1.0 - 2.0 * MARGIN as f64);
    let expected = 0.5 * 0.8 * scale * scale;
    // Flat face, one normal: the interior has one colour; take it near the centroid.
    let fill = image.pixel(150, 290).unwrap();
    assert_ne!(fill, WHITE);
    let area = coverage(&image, fill, WHITE);
    assert!((area / expected - 1.0).abs() < 0.01, "{area} vs {expected}");
    // Its corners land where the framing puts them (20 px margin, y down).
    let (x0, y0, x1, y1) = bbox_of(&image, |c| c != WHITE).unwrap();
    assert!(x0.abs_diff(20) <= 1 && x1.abs_diff(380) <= 1, "{x0}..{x1}");
    assert!(
        y1.abs_diff(380) <= 1 && y0.abs_diff(380 - 288) <= 1,
        "{y0}..{y1}"
    );
}

#[test]
fn a_box_fills_the_image_minus_the_margin_on_its_limiting_axis_from_every_view() {
    // Extents 1 (x) × 2 (y) × 3 (z), off the origin.
    let (positions, faces) = cuboid([1.0, -1.0, 2.0], [2.0, 1.0, 5.0]);
    let (w, h) = (360u32, 300u32);
    for view in View::ALL {
        let image = render(&positions, &faces, None, &options(w, h, view)).unwrap();
        let (right, up, _) = view.axes();
        let extent = |axis: [f32; 3]| -> f64 {
            axis.iter()
                .zip([1.0, 2.0, 3.0])
                .map(|(a, e)| (a * e).abs() as f64)
                .sum()
        };
        let (du, dv) = (extent(right), extent(up));
        let avail = (1.0 - 2.0 * MARGIN as f64) * [w as f64, h as f64][0];
        let avail_h = (1.0 - 2.0 * MARGIN as f64) * h as f64;
        let scale = (avail / du).min(avail_h / dv);
        let (pw, ph) = (du * scale, dv * scale);
        // One face seen head-on: uniform colour; the sides are edge-on and draw nothing.
        let fill = image.pixel(w / 2, h / 2).unwrap();
        let area = coverage(&image, fill, WHITE);
        assert!(
            (area / (pw * ph) - 1.0).abs() < 0.02,
            "{view}: {area} vs {}",
            pw * ph
        );
        let (x0, y0, x1, y1) = bbox_of(&image, |c| c != WHITE).unwrap();
        let (bw, bh) = ((x1 - x0 + 1) as f64, (y1 - y0 + 1) as f64);
        assert!(
            (bw - pw).abs() <= 2.0 && (bh - ph).abs() <= 2.0,
            "{view}: {bw}x{bh} vs {pw}x{ph}"
        );
        // Centred, and touching the margin on the limiting axis.
        assert!(
            ((x0 + x1) as f64 / 2.0 - w as f64 / 2.0).abs() <= 1.0,
            "{view}"
        );
        assert!(
            ((y0 + y1) as f64 / 2.0 - h as f64 / 2.0).abs() <= 1.0,
            "{view}"
        );
        let limited_by_height = avail_h / dv < avail / du;
        if limited_by_height {
            assert!((bh - avail_h).abs() <= 2.0, "{view}: {bh}");
        } else {
            assert!((bw - avail).abs() <= 2.0, "{view}: {bw}");
        }
    }
}

#[test]
fn each_view_puts_the_axes_on_the_expected_sides() {
    // Markers: red at +x, green at +y, blue at +z, around a grey centre cube.
    let mut mesh = cuboid([-0.2; 3], [0.2; 3]);
    let markers = [
        ([1.0, 0.0, 0.0], [230, 20, 20]),
        ([0.0, 1.0, 0.0], [20, 200, 20]),
        ([0.0, 0.0, 1.0], [20, 20, 230]),
    ];
    let mut colors = vec![[128u8; 3]; 8];
    for (c, color) in markers {
        append(&mut mesh, tetrahedron(c, 0.15));
        colors.extend([color; 4]);
    }
    let (w, h) = (200, 200);
    for view in View::ALL {
        let o = RenderOptions {
            frame: Some(Bounds {
                min: [-1.2; 3],
                max: [1.2; 3],
            }),
            ..options(w, h, view)
        };
        let image = render(&mesh.0, &mesh.1, Some(&colors), &o).unwrap();
        let (right, up, toward) = view.axes();
        for (k, (c, _)) in markers.iter().enumerate() {
            let dominant = |p: [u8; 3]| {
                let m = p.iter().copied().max().unwrap();
                p[k] == m
                    && m > 40
                    && p.iter()
                        .filter(|&&v| u16::from(v) + 30 < u16::from(m))
                        .count()
                        == 2
            };
            let found = centroid(&image, dominant);
            let along = |a: [f32; 3]| a.iter().zip(c).map(|(x, y)| x * y).sum::<f32>();
            if along(toward) < 0.0 {
                // Behind the centre cube: hidden.
                assert!(
                    found.is_none_or(|f| f.1 < 5),
                    "{view}: marker {k} should be hidden"
                );
                continue;
            }
            let ([cx, cy], n) = found.unwrap_or_else(|| panic!("{view}: marker {k} not drawn"));
            assert!(n > 20, "{view}: marker {k}: {n} pixels");
            let (dx, dy) = (cx - w as f64 / 2.0, cy - h as f64 / 2.0);
            let expect = |v: f32| {
                if v > 0.0 {
                    1.0
                } else if v < 0.0 {
                    -1.0
                } else {
                    0.0
                }
            };
            let (ex, ey) = (expect(along(right)), -expect(along(up)));
            for (d, e, axis) in [(dx, ex, "x"), (dy, ey, "y")] {
                if e == 0.0 {
                    assert!(
                        d.abs() < 5.0,
                        "{view}: marker {k} off centre in {axis}: {d}"
                    );
                } else {
                    assert!(
                        d * e > 50.0,
                        "{view}: marker {k} on the wrong side in {axis}: {d}"
                    );
                }
            }
        }
    }
}

#[test]
fn the_nearest_face_wins_whatever_the_drawing_order() {
    // Two overlapping squares: red at z = 1 (near the front camera), blue at z = 0.
    let square = |z: f32, dx: f32| {
        vec![
            [dx, 0.0, z],
            [dx + 1.0, 0.0, z],
            [dx + 1.0, 1.0, z],
            [dx, 1.0, z],
        ]
    };
    let mut positions = square(1.0, 0.0);
    positions.extend(square(0.0, 0.5));
    let colors: Vec<[u8; 3]> = [[220, 30, 30]; 4]
        .into_iter()
        .chain([[30, 30, 220]; 4])
        .collect();
    let red_first = vec![[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]];
    let blue_first: Vec<[u32; 3]> = red_first.iter().rev().copied().collect();
    let is_red = |p: [u8; 3]| u16::from(p[0]) > 2 * u16::from(p[2].max(10));
    let is_blue = |p: [u8; 3]| u16::from(p[2]) > 2 * u16::from(p[0].max(10));
    for (faces, view, near_is_red) in [
        (&red_first, View::Front, true),
        (&blue_first, View::Front, true),
        (&red_first, View::Back, false),
        (&blue_first, View::Back, false),
    ] {
        let image = render(&positions, faces, Some(&colors), &options(300, 200, view)).unwrap();
        // The overlap, x in [0.5, 1], is in the middle of the picture.
        let overlap = image.pixel(150, 100).unwrap();
        assert_eq!(is_red(overlap), near_is_red, "{view}: {overlap:?}");
        assert_eq!(is_blue(overlap), !near_is_red, "{view}: {overlap:?}");
        // Each square still shows its own part.
        let red = centroid(&image, is_red).unwrap().1;
        let blue = centroid(&image, is_blue).unwrap().1;
        let (more, less) = if near_is_red {
            (red, blue)
        } else {
            (blue, red)
        };
        assert!(
            more > (less as f64 * 1.7) as usize,
            "{view}: {more} vs {less}"
        );
    }
}

#[test]
fn faces_towards_the_viewer_are_brighter_than_grazing_ones_and_back_faces_are_shaded() {
    let angle = 80f32.to_radians();
    let positions = [
        // Facing the front camera, centred at x = -1.
        [-1.5, -0.5, 0.0],
        [-0.5, -0.5, 0.0],
        [-1.0, 0.5, 0.0],
        // Turned by 80° about y, centred at x = 1: seen almost edge-on.
        [1.0 - 0.5 * angle.cos(), -0.5, 0.5 * angle.sin()],
        [1.0 + 0.5 * angle.cos(), -0.5, -0.5 * angle.sin()],
        [1.0, 0.5, 0.0],
    ];
    let faces = [[0, 1, 2], [3, 4, 5]];
    let frame = Some(Bounds {
        min: [-1.6, -0.6, -1.0],
        max: [1.6, 0.6, 1.0],
    });
    let o = RenderOptions {
        frame,
        ..options(320, 120, View::Front)
    };
    let image = render(&positions, &faces, None, &o).unwrap();
    let lum_at = |x: u32| luminance(image.pixel(x, 62).unwrap());
    let (head_on, grazing) = (lum_at(70), lum_at(250));
    assert!(grazing < 250.0, "the grazing face is drawn");
    assert!(head_on > grazing + 40.0, "{head_on} vs {grazing}");
    // Seen from the back, the head-on face shows its back side: shaded, not background, darker.
    let back = render(
        &positions,
        &faces,
        None,
        &RenderOptions {
            view: View::Back,
            ..o
        },
    )
    .unwrap();
    let back_lum = luminance(back.pixel(250, 62).unwrap());
    assert!(back_lum < 240.0 && back_lum > 60.0, "{back_lum}");
    assert!(back_lum < head_on, "{back_lum} vs {head_on}");
}

#[test]
fn colours_are_interpolated_and_a_shared_frame_keeps_the_scale() {
    let (positions, faces) = cuboid([0.0; 3], [1.0; 3]);
    let colors: Vec<[u8; 3]> = positions
        .iter()
        .map(|p| {
            if p[0] > 0.5 {
                [240, 40, 40]
            } else {
                [40, 40, 240]
            }
        })
        .collect();
    let image = render(
        &positions,
        &faces,
        Some(&colors),
        &options(200, 200, View::Front),
    )
    .unwrap();
    let left = image.pixel(30, 100).unwrap();
    let right = image.pixel(170, 100).unwrap();
    let mid = image.pixel(100, 100).unwrap();
    let twice = |a: u8, b: u8| u16::from(a) > 2 * u16::from(b);
    assert!(
        twice(left[2], left[0]) && twice(right[0], right[2]),
        "{left:?} {right:?}"
    );
    assert!(mid[0].abs_diff(mid[2]) < 30, "{mid:?}");
    // The same cube framed with a box twice as large covers a quarter of the area.
    let frame = Some(Bounds {
        min: [-0.5, -0.5, 0.0],
        max: [1.5, 1.5, 1.0],
    });
    let small = render(
        &positions,
        &faces,
        None,
        &RenderOptions {
            frame,
            ..options(200, 200, View::Front)
        },
    )
    .unwrap();
    let big = render(&positions, &faces, None, &options(200, 200, View::Front)).unwrap();
    let fill = small.pixel(100, 100).unwrap();
    let ratio = coverage(&small, fill, WHITE) / coverage(&big, fill, WHITE);
    assert!((ratio - 0.25).abs() < 0.01, "{ratio}");
}

#[test]
fn the_background_option_and_a_real_horse_render() {
    let (positions, faces) = cuboid([0.0; 3], [1.0; 3]);
    let o = RenderOptions {
        background: [10, 20, 30],
        ..options(64, 48, View::Top)
    };
    let image = render(&positions, &faces, None, &o).unwrap();
    assert_eq!(image.pixel(0, 0), Some([10, 20, 30]));
    assert_eq!((image.width, image.height), (64, 48));

    let Some(dir) = mesh_io::datasets::find_or_skip("horse-gallop") else {
        return;
    };
    let set = mesh_io::load_set(&dir).unwrap().value;
    let image = render(
        set.frame(0),
        set.faces(),
        None,
        &options(160, 120, View::Left),
    )
    .unwrap();
    let covered = image.rgb.chunks_exact(3).filter(|p| p != &WHITE).count();
    let fraction = covered as f64 / (160.0 * 120.0);
    // A galloping horse from the side: body, legs and tail, far from empty or full.
    assert!((0.12..0.6).contains(&fraction), "{fraction}");
}

#[test]
fn the_default_auto_view_shows_long_shapes_broadside_and_the_horse_side_on() {
    // The synthetic capsule lies along z: the front view sees a disc, auto sees its length.
    let capsule = mesh_io::synth::rest_capsule(&mesh_io::synth::SynthConfig::default());
    let (w, h) = (200, 200);
    let drawn = |view: View| {
        let image = render(
            &capsule.positions,
            &capsule.faces,
            None,
            &options(w, h, view),
        )
        .unwrap();
        let (x0, y0, x1, y1) = bbox_of(&image, |c| c != WHITE).unwrap();
        (f64::from(x1 - x0 + 1), f64::from(y1 - y0 + 1))
    };
    assert_eq!(RenderOptions::default().view, View::Auto);
    let (fw, fh) = drawn(View::Front);
    assert!((fw / fh - 1.0).abs() < 0.5, "front: {fw} x {fh}");
    // Axis 5 long, at most 1.4 wide: the long side spans the image minus its margins.
    let (aw, ah) = drawn(View::Auto);
    let (long, short) = (aw.max(ah), aw.min(ah));
    assert!(
        (long - 0.9 * f64::from(w)).abs() <= 2.0,
        "auto: {aw} x {ah}"
    );
    assert!(long > 3.0 * short, "auto: {aw} x {ah}");

    let Some(dir) = mesh_io::datasets::find_or_skip("horse-gallop") else {
        return;
    };
    let files = mesh_io::set::list_mesh_files(&dir).unwrap();
    let horse = mesh_io::read_mesh(&files[0]).unwrap().value;
    let bounds = Bounds::of(&[&horse.positions]).unwrap();
    // Head to tail along z, thinnest across x: seen from the side, standing.
    assert_eq!(View::Auto.resolve(&bounds), View::Left);
    let image = render(
        &horse.positions,
        &horse.faces,
        None,
        &options(w, h, View::Auto),
    )
    .unwrap();
    let (x0, y0, x1, y1) = bbox_of(&image, |c| c != WHITE).unwrap();
    let (bw, bh) = (f64::from(x1 - x0 + 1), f64::from(y1 - y0 + 1));
    assert!(bw > 1.3 * bh, "{bw} x {bh}");
}
