//! Sheets, colour bars, side-by-side panels, scatter plots and PNG files.

mod common;

use common::*;
use mesh_render::colormap::{ERROR_STOPS, error_color};
use mesh_render::*;

fn solid(width: u32, height: u32, color: [u8; 3]) -> Image {
    Image::filled(width, height, color).unwrap()
}

#[test]
fn png_round_trip_in_memory_and_on_disk() {
    let (w, h) = (37, 23);
    let rgb: Vec<u8> = (0..w * h * 3).map(|i| (i * 7 % 256) as u8).collect();
    let image = Image {
        width: w,
        height: h,
        rgb,
    };
    let bytes = image.encode_png().unwrap();
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
    // Decode with the png crate directly, not only through our own decoder.
    let mut reader = png::Decoder::new(std::io::Cursor::new(&bytes))
        .read_info()
        .unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(
        (info.width, info.height, info.color_type),
        (w, h, png::ColorType::Rgb)
    );
    assert_eq!(&buf[..info.buffer_size()], &image.rgb[..]);
    assert_eq!(Image::decode_png(&bytes).unwrap(), image);

    let dir = std::env::temp_dir().join(format!("mesh-render-png-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("x.png");
    image.save_png(&path).unwrap();
    assert_eq!(Image::load_png(&path).unwrap(), image);
    // Nothing but the picture is left in the folder (no temporary file).
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn hstack_and_sheet_dimensions_and_placement() {
    let a = solid(30, 20, [255, 0, 0]);
    let b = solid(10, 40, [0, 0, 255]);
    let stacked = hstack(&[a.clone(), b.clone()]).unwrap();
    assert_eq!((stacked.width, stacked.height), (40, 40));
    assert_eq!(stacked.pixel(0, 10), Some([255, 0, 0])); // centred: rows 10..30
    assert_eq!(stacked.pixel(0, 5), Some(WHITE));
    assert_eq!(stacked.pixel(35, 0), Some([0, 0, 255]));

    let tiles: Vec<Tile> = (0..7)
        .map(|i| Tile {
            image: solid(100, 80, [200, 200, 220]),
            caption: format!("mesh {i}"),
        })
        .collect();
    let s = sheet(&tiles, 3).unwrap();
    let band = caption_height(100);
    assert!((15..60).contains(&band), "{band}");
    assert_eq!((s.width, s.height), (300, 3 * (80 + band)));
    // Tile 4 sits in row 1, column 1; the empty cells of the last row stay white.
    assert_eq!(s.pixel(150, 80 + band + 40), Some([200, 200, 220]));
    assert_eq!(s.pixel(250, 2 * (80 + band) + 40), Some(WHITE));
    // Every caption draws dark text in the band under its tile, centred.
    for i in 0..7u32 {
        let (x0, y0) = ((i % 3) * 100, (i / 3) * (80 + band) + 80);
        let dark = count_in(&s, (x0, y0, x0 + 100, y0 + band), is_dark);
        assert!(dark > 15, "caption {i}: {dark} dark pixels");
        let left = count_in(&s, (x0, y0, x0 + 15, y0 + band), is_dark);
        assert_eq!(left, 0, "caption {i} is not centred");
    }
    // Fewer tiles than columns: the sheet is only as wide as the tiles.
    assert_eq!(sheet(&tiles[..2], 5).unwrap().width, 200);
}

#[test]
fn the_colour_bar_shows_the_map_ticks_and_label() {
    let image = solid(200, 300, [180, 180, 180]);
    let out = with_colorbar(&image, 0.0123, "error (m)").unwrap();
    assert_eq!(out.height, 300);
    assert!(out.width > 240 && out.width < 400, "{}", out.width);
    // The original picture is unchanged on the left.
    assert_eq!(out.pixel(100, 150), Some([180, 180, 180]));
    let panel = (200, 0, out.width, 300);
    // The gradient: the map's first colour near the bottom of the bar, its last near the top.
    let near = |a: [u8; 3], b: [u8; 3]| a.iter().zip(b).all(|(x, y)| x.abs_diff(y) <= 6);
    let low = centroid(&out, |p| near(p, error_color(0.02))).unwrap().0;
    let high = centroid(&out, |p| near(p, ERROR_STOPS[4])).unwrap().0;
    assert!(low[0] > 200.0 && high[0] > 200.0);
    assert!(
        high[1] < 100.0 && low[1] > 200.0,
        "top {high:?}, bottom {low:?}"
    );
    // Tick labels and the vertical label are dark text right of the bar.
    let bar_right = low[0] as u32 + 12;
    let text = count_in(&out, (bar_right, 0, panel.2, 300), is_dark);
    assert!(text > 60, "{text} dark pixels");
    // The label, rightmost, is written vertically: taller than wide, centred on the bar.
    let right = Image {
        width: 25,
        height: 300,
        rgb: (0..300u32)
            .flat_map(|y| (out.width - 25..out.width).flat_map(move |x| [x, y]))
            .collect::<Vec<u32>>()
            .chunks(2)
            .flat_map(|xy| out.pixel(xy[0], xy[1]).unwrap())
            .collect(),
    };
    let (x0, y0, x1, y1) = bbox_of(&right, is_dark).unwrap();
    assert!(
        y1 - y0 > 35 && y1 - y0 > 2 * (x1 - x0),
        "{:?}",
        (x0, y0, x1, y1)
    );
    assert!(((y0 + y1) as i32 / 2 - 150).abs() < 10);
    // max = 0 is fine (a single "0" tick).
    assert_eq!(with_colorbar(&image, 0.0, "").unwrap().height, 300);
}

#[test]
fn scatter_draws_points_where_the_data_are() {
    let series = [Series {
        name: String::new(),
        points: vec![[0.0, 0.0], [10.0, 10.0], [10.0, 0.0]],
        joined: false,
        color_by_order: false,
    }];
    let (w, h) = (400, 300);
    let image = scatter("Title", "x axis", "y axis", &series, w, h).unwrap();
    assert_eq!((image.width, image.height), (w, h));
    let c = SERIES_COLORS[0];
    let is_point = |p: [u8; 3]| p.iter().zip(c).all(|(a, b)| a.abs_diff(b) <= 10);
    let quadrant = |qx: u32, qy: u32| {
        count_in(
            &image,
            (qx * w / 2, qy * h / 2, (qx + 1) * w / 2, (qy + 1) * h / 2),
            is_point,
        )
    };
    assert!(quadrant(0, 1) > 10, "(0, 0) is bottom left");
    assert!(quadrant(1, 0) > 10, "(10, 10) is top right");
    assert!(quadrant(1, 1) > 10, "(10, 0) is bottom right");
    assert_eq!(quadrant(0, 0), 0, "nothing top left");
    // The title and axis labels are text.
    assert!(
        count_in(&image, (w / 3, 0, 2 * w / 3, 30), is_dark) > 20,
        "title"
    );
    assert!(
        count_in(&image, (0, h / 4, 20, 3 * h / 4), is_dark) > 5,
        "y label"
    );

    // Joined and coloured by order: first point dark violet, last yellow, a line between.
    let path = [Series {
        name: "path".into(),
        points: (0..20)
            .map(|i| [i as f32, (i as f32 * 0.3).sin()])
            .collect(),
        joined: true,
        color_by_order: true,
    }];
    let image = scatter("Path", "t", "sin", &path, w, h).unwrap();
    let violet = centroid(&image, |p| {
        p[2] > 60 && p[0] < 90 && p[1] < 40 && p[2] > p[0]
    })
    .unwrap()
    .0;
    let yellow = centroid(&image, |p| p[0] > 200 && p[1] > 200 && p[2] < 80)
        .unwrap()
        .0;
    assert!(violet[0] < yellow[0] - 150.0, "{violet:?} {yellow:?}");
}

#[test]
fn bad_input_is_a_typed_error_not_a_panic() {
    let (positions, faces) = cuboid([0.0; 3], [1.0; 3]);
    let o = RenderOptions::default();
    let err = |r: Result<Image, RenderError>| r.unwrap_err().to_string();

    let zero = RenderOptions {
        width: 0,
        ..o.clone()
    };
    assert!(err(render(&positions, &faces, None, &zero)).contains("width"));
    let huge = RenderOptions {
        width: 100_000,
        height: 100_000,
        ..o.clone()
    };
    assert!(matches!(
        render(&positions, &faces, None, &huge),
        Err(RenderError::Size { .. })
    ));
    assert!(matches!(
        render(&[], &faces, None, &o),
        Err(RenderError::Empty {
            argument: "positions"
        })
    ));
    assert!(matches!(
        render(&positions, &[], None, &o),
        Err(RenderError::Empty { argument: "faces" })
    ));
    let mut nan = positions.clone();
    nan[3][1] = f32::NAN;
    let e = err(render(&nan, &faces, None, &o));
    assert!(
        e.contains("positions") && e.contains("item 3") && e.contains("NaN"),
        "{e}"
    );
    let mut bad_faces = faces.clone();
    bad_faces[5] = [0, 1, 8];
    let e = err(render(&positions, &bad_faces, None, &o));
    assert!(
        e.contains("face 5") && e.contains("vertex 8") && e.contains("8 vertices"),
        "{e}"
    );
    let e = err(render(&positions, &faces, Some(&[[0; 3]; 7]), &o));
    assert!(e.contains("colors") && e.contains("7 entries for 8"), "{e}");
    let bad_frame = RenderOptions {
        frame: Some(Bounds {
            min: [1.0; 3],
            max: [0.0; 3],
        }),
        ..o.clone()
    };
    assert!(err(render(&positions, &faces, None, &bad_frame)).contains("frame"));

    let tile = Tile {
        image: solid(4, 4, WHITE),
        caption: "a".into(),
    };
    assert!(err(sheet(std::slice::from_ref(&tile), 0)).contains("columns"));
    assert!(matches!(
        sheet(&[], 2),
        Err(RenderError::Empty { argument: "tiles" })
    ));
    let broken = Tile {
        image: Image {
            width: 4,
            height: 4,
            rgb: vec![0; 5],
        },
        caption: "b".into(),
    };
    assert!(err(sheet(&[tile, broken], 2)).contains("5 bytes"));
    assert!(matches!(
        hstack(&[]),
        Err(RenderError::Empty { argument: "images" })
    ));

    let image = solid(10, 10, WHITE);
    for max in [f32::NAN, f32::INFINITY, -1.0] {
        assert!(
            err(with_colorbar(&image, max, "e")).contains("max"),
            "{max}"
        );
    }
    let series = |points: Vec<[f32; 2]>| {
        vec![Series {
            points,
            ..Default::default()
        }]
    };
    assert!(matches!(
        scatter("t", "x", "y", &series(vec![]), 300, 200),
        Err(RenderError::Empty { .. })
    ));
    let e = err(scatter(
        "t",
        "x",
        "y",
        &series(vec![[0.0, 1.0], [f32::NAN, 0.0]]),
        300,
        200,
    ));
    assert!(e.contains("point 1") && e.contains("not finite"), "{e}");
    assert!(err(scatter("t", "x", "y", &series(vec![[0.0, 1.0]]), 50, 200)).contains("at least"));

    assert!(matches!(
        Image::decode_png(b"not a png"),
        Err(RenderError::Png { .. })
    ));
    let missing = std::env::temp_dir().join("mesh-render-no-such-dir/x.png");
    let e = err(image.save_png(&missing).map(|_| image.clone()));
    assert!(e.contains("mesh-render-no-such-dir"), "{e}");
    assert!(!missing.exists());
}
