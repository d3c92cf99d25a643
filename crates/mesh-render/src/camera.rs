//! Where the camera looks from ([`View`]), what it frames ([`Bounds`]), and the mapping from
//! world coordinates to (supersampled) pixel coordinates.

use crate::error::RenderError;
use std::str::FromStr;

/// The side the orthographic camera looks from. Axes are the mesh's own: `Front` looks along −z
/// with y up and x to the right; `Left` stands on the −x side, `Top` on the +y side (with −z up
/// on screen, so the front of the object is at the bottom of the picture), and so on. `Auto`
/// (the default) picks one of those six from the box being framed: see [`View::resolve`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum View {
    #[default]
    Auto,
    Front,
    Back,
    Left,
    Right,
    Top,
    Bottom,
}

impl View {
    /// Every fixed view (all but [`View::Auto`]), in declaration order.
    pub const ALL: [View; 6] = [
        View::Front,
        View::Back,
        View::Left,
        View::Right,
        View::Top,
        View::Bottom,
    ];

    /// The camera's axes in world coordinates: `(right, up, toward the viewer)`, a right-handed
    /// orthonormal frame (`right × up = toward`). `Auto` has no axes of its own until
    /// [resolved](View::resolve) against a box; unresolved, it gives the front view's.
    pub fn axes(self) -> ([f32; 3], [f32; 3], [f32; 3]) {
        match self {
            View::Auto | View::Front => ([1., 0., 0.], [0., 1., 0.], [0., 0., 1.]),
            View::Back => ([-1., 0., 0.], [0., 1., 0.], [0., 0., -1.]),
            View::Left => ([0., 0., 1.], [0., 1., 0.], [-1., 0., 0.]),
            View::Right => ([0., 0., -1.], [0., 1., 0.], [1., 0., 0.]),
            View::Top => ([1., 0., 0.], [0., 0., -1.], [0., 1., 0.]),
            View::Bottom => ([1., 0., 0.], [0., 0., 1.], [0., -1., 0.]),
        }
    }

    /// The fixed view that `self` stands for when framing `bounds`: a fixed view is itself;
    /// `Auto` looks along the box's thinnest axis, so the shape is seen broadside rather than
    /// end-on, and keeps the mesh's y axis up whenever y is not that axis, because mesh files
    /// are conventionally y-up (glTF requires it; the OBJ sets meshvae uses follow it), so
    /// standing shapes stay standing: thinnest x → [`View::Left`], thinnest z →
    /// [`View::Front`], and a shape flat in y → [`View::Top`]. Ties go to z, then x, then y
    /// (front before side before top), so a cube is seen from the front.
    pub fn resolve(self, bounds: &Bounds) -> View {
        if self != View::Auto {
            return self;
        }
        let extent = |k: usize| bounds.max[k] - bounds.min[k];
        // Preference order on ties; `min_by` keeps the first of equal elements.
        let thinnest = [2, 0, 1]
            .into_iter()
            .min_by(|&a, &b| extent(a).total_cmp(&extent(b)))
            .unwrap_or(2);
        match thinnest {
            0 => View::Left,
            1 => View::Top,
            _ => View::Front,
        }
    }

    /// The view of every picture of a mesh set: [`View::Auto`] resolved against the set's rest
    /// mesh `rest` (its first), not against the meshes one picture happens to show, so that
    /// every sheet of one set looks from the same side (a set of capsules bent in one plane
    /// would otherwise be seen lengthwise on one sheet and across on the next). A fixed view
    /// is itself, as is `Auto` for an empty mesh.
    pub fn for_set(self, rest: &[[f32; 3]]) -> View {
        match Bounds::of(&[rest]) {
            Some(bounds) => self.resolve(&bounds),
            None => self,
        }
    }

    /// The lower-case name (`auto`, `front`, `back`, …), as accepted by [`View::from_str`].
    pub fn name(self) -> &'static str {
        match self {
            View::Auto => "auto",
            View::Front => "front",
            View::Back => "back",
            View::Left => "left",
            View::Right => "right",
            View::Top => "top",
            View::Bottom => "bottom",
        }
    }
}

impl std::fmt::Display for View {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for View {
    type Err = RenderError;

    /// Parses `auto|front|back|left|right|top|bottom` (case-insensitive).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        std::iter::once(View::Auto)
            .chain(View::ALL)
            .find(|v| v.name().eq_ignore_ascii_case(s))
            .ok_or_else(|| {
                RenderError::invalid(
                    "view",
                    format!(
                        "unknown view {s:?} (expected auto, front, back, left, right, top or \
                         bottom)"
                    ),
                )
            })
    }
}

/// An axis-aligned box; the camera frames it so that several meshes rendered with one `Bounds`
/// are drawn at one scale and position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bounds {
    pub min: [f32; 3],
    pub max: [f32; 3],
}

impl Bounds {
    /// The smallest box holding every finite point of every frame; `None` when there is none.
    pub fn of(frames: &[&[[f32; 3]]]) -> Option<Bounds> {
        let mut points = frames
            .iter()
            .flat_map(|f| f.iter())
            .filter(|p| p.iter().all(|c| c.is_finite()));
        let first = *points.next()?;
        Some(points.fold(
            Bounds {
                min: first,
                max: first,
            },
            |b, p| Bounds {
                min: std::array::from_fn(|k| b.min[k].min(p[k])),
                max: std::array::from_fn(|k| b.max[k].max(p[k])),
            },
        ))
    }

    /// The picture size, at most `size` × `size`, that frames the box seen from `view` with
    /// the same margins on both sides: a long, low shape gets a wide, low picture instead of a
    /// square one with empty bands above and below (the shorter side is kept to at least a
    /// quarter of `size`).
    pub fn fit(&self, view: View, size: u32) -> (u32, u32) {
        let (right, up, _) = view.resolve(self).axes();
        let (du, dv) = (self.extent_along(right), self.extent_along(up));
        let short = |ratio: f32| {
            let side = (size as f32 * ratio).round() as u32;
            side.clamp(size.div_ceil(4), size)
        };
        match (du > 0.0, dv > 0.0) {
            (true, true) if du >= dv => (size, short(dv / du)),
            (true, true) => (short(du / dv), size),
            _ => (size, size),
        }
    }

    /// The box's extent along the unit direction `d`.
    fn extent_along(&self, d: [f32; 3]) -> f32 {
        (0..3)
            .map(|k| (self.max[k] - self.min[k]) * d[k].abs())
            .sum()
    }

    /// The box grown to hold `other` too.
    pub fn union(&self, other: &Bounds) -> Bounds {
        Bounds {
            min: std::array::from_fn(|k| self.min[k].min(other.min[k])),
            max: std::array::from_fn(|k| self.max[k].max(other.max[k])),
        }
    }

    pub(crate) fn validate(&self, argument: &'static str) -> Result<(), RenderError> {
        let finite = self.min.iter().chain(&self.max).all(|c| c.is_finite());
        if !finite || (0..3).any(|k| self.min[k] > self.max[k]) {
            return Err(RenderError::invalid(
                argument,
                format!(
                    "min {:?} and max {:?} are not a finite box with min <= max",
                    self.min, self.max
                ),
            ));
        }
        Ok(())
    }
}

/// Fraction of the image width (height) left empty on each side of the framed box, on the
/// limiting axis.
pub const MARGIN: f32 = 0.05;

/// World → pixel mapping for one view and frame: `x = cx + s (p·right − u0)`, `y = cy − s (p·up −
/// v0)` (y grows downwards), depth `p·toward` (larger is nearer).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Projection {
    pub right: [f32; 3],
    pub up: [f32; 3],
    pub toward: [f32; 3],
    scale: f32,
    u0: f32,
    v0: f32,
    cx: f32,
    cy: f32,
}

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

impl Projection {
    /// Frames `bounds` in a `width × height` pixel grid with [`MARGIN`], keeping the aspect ratio;
    /// [`View::Auto`] is resolved against `bounds`.
    pub fn new(view: View, bounds: &Bounds, width: u32, height: u32) -> Projection {
        let (right, up, toward) = view.resolve(bounds).axes();
        let (mut u_lo, mut u_hi, mut v_lo, mut v_hi) = (f32::MAX, f32::MIN, f32::MAX, f32::MIN);
        for corner in 0..8 {
            let p = std::array::from_fn(|k| {
                if corner >> k & 1 == 0 {
                    bounds.min[k]
                } else {
                    bounds.max[k]
                }
            });
            let (u, v) = (dot(p, right), dot(p, up));
            (u_lo, u_hi, v_lo, v_hi) = (u_lo.min(u), u_hi.max(u), v_lo.min(v), v_hi.max(v));
        }
        let avail_w = width as f32 * (1.0 - 2.0 * MARGIN);
        let avail_h = height as f32 * (1.0 - 2.0 * MARGIN);
        let (du, dv) = (u_hi - u_lo, v_hi - v_lo);
        let scale = match (du > 0.0, dv > 0.0) {
            (true, true) => (avail_w / du).min(avail_h / dv),
            (true, false) => avail_w / du,
            (false, true) => avail_h / dv,
            // A box without extent on screen: nothing visible is drawn anyway.
            (false, false) => 1.0,
        };
        Projection {
            right,
            up,
            toward,
            scale,
            u0: 0.5 * (u_lo + u_hi),
            v0: 0.5 * (v_lo + v_hi),
            cx: 0.5 * width as f32,
            cy: 0.5 * height as f32,
        }
    }

    /// Pixel coordinates and depth of a world point.
    pub fn project(&self, p: [f32; 3]) -> [f32; 3] {
        [
            self.cx + self.scale * (dot(p, self.right) - self.u0),
            self.cy - self.scale * (dot(p, self.up) - self.v0),
            dot(p, self.toward),
        ]
    }

    /// A world direction in camera axes (right, up, toward).
    pub fn rotate(&self, d: [f32; 3]) -> [f32; 3] {
        [dot(d, self.right), dot(d, self.up), dot(d, self.toward)]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    }

    #[test]
    fn every_view_is_a_right_handed_orthonormal_frame_looking_from_its_side() {
        for view in View::ALL {
            let (r, u, t) = view.axes();
            assert_eq!(cross(r, u), t, "{view}");
            assert_eq!(dot(r, u), 0.0, "{view}");
            assert_eq!(view.name().parse::<View>().unwrap(), view);
        }
        // The camera stands on the named side: `toward` points from the object to it.
        assert_eq!(View::Front.axes().2, [0., 0., 1.]);
        assert_eq!(View::Left.axes().2, [-1., 0., 0.]);
        assert_eq!(View::Top.axes().2, [0., 1., 0.]);
        assert!("sideways".parse::<View>().is_err());
        assert_eq!("AUTO".parse::<View>().unwrap(), View::Auto);
        assert_eq!(View::default(), View::Auto);
    }

    #[test]
    fn auto_looks_along_the_thinnest_axis_and_shows_the_long_axis_in_full() {
        for long in 0..3 {
            for thin in (0..3).filter(|&k| k != long) {
                // Extents 4 along `long`, 0.5 along `thin`, 1 along the third axis.
                let mut max = [1.0f32; 3];
                max[long] = 4.0;
                max[thin] = 0.5;
                let bounds = Bounds {
                    min: [-1.0, 2.0, 0.5],
                    max: std::array::from_fn(|k| max[k] + [-1.0, 2.0, 0.5][k]),
                };
                let view = View::Auto.resolve(&bounds);
                assert_ne!(view, View::Auto);
                let (right, up, toward) = view.axes();
                let axis = |k: usize| -> [f32; 3] { std::array::from_fn(|j| f32::from(j == k)) };
                let case = format!("long {long}, thin {thin}: {view}");
                assert_eq!(dot(toward, axis(thin)).abs(), 1.0, "{case}");
                // The long axis lies in the picture plane: it is the right or the up axis.
                let on_screen = dot(right, axis(long)).abs() + dot(up, axis(long)).abs();
                assert_eq!(on_screen, 1.0, "{case}");
                // y stays up unless y is the thinnest axis.
                if thin != 1 {
                    assert_eq!(up, [0.0, 1.0, 0.0], "{case}");
                }
                // Drawn, the box's long axis is its longer side on screen.
                let p = Projection::new(View::Auto, &bounds, 100, 100);
                let (lo, hi) = (p.project(bounds.min), p.project(bounds.max));
                let (w, h) = ((hi[0] - lo[0]).abs(), (hi[1] - lo[1]).abs());
                assert!((w.max(h) - 90.0).abs() < 1e-3, "{case}: {w} x {h}");
                assert!((w.min(h) - 22.5).abs() < 1e-3, "{case}: {w} x {h}");
            }
        }
        // Fixed views are themselves; ties prefer front, then the side, then the top.
        let cube = Bounds {
            min: [0.0; 3],
            max: [1.0; 3],
        };
        assert_eq!(View::Top.resolve(&cube), View::Top);
        assert_eq!(View::Auto.resolve(&cube), View::Front);
        let long_z = Bounds {
            min: [0.0; 3],
            max: [1.0, 1.0, 2.0],
        };
        assert_eq!(View::Auto.resolve(&long_z), View::Left);
    }

    #[test]
    fn one_set_is_seen_from_one_side_and_pictures_fit_its_aspect() {
        // A rod along z, round in x and y (a rest capsule), and two of its poses bent in the
        // y-z plane: framed alone, the poses' box is thinnest in x; the set's view follows
        // the rest mesh wherever the pictures' boxes would pick another side.
        let rest = [[-0.1, -0.1, -1.0], [0.1, 0.1, 1.0]];
        let bent = Bounds {
            min: [-0.1, -0.1, -0.8],
            max: [0.1, 0.5, 0.8],
        };
        let flat_in_x = Bounds {
            min: [-0.1, -0.6, -0.2],
            max: [0.1, 0.6, 0.2],
        };
        let view = View::Auto.for_set(&rest);
        assert_eq!(view, View::Left);
        assert_eq!(View::Auto.resolve(&bent), View::Left);
        assert_eq!(View::Auto.resolve(&flat_in_x), View::Left);
        let flat_in_z = Bounds {
            min: [-0.6, -0.6, -0.1],
            max: [0.6, 0.6, 0.1],
        };
        assert_eq!(View::Auto.resolve(&flat_in_z), View::Front);
        assert_eq!(view.resolve(&flat_in_z), View::Left, "a fixed view stays");
        assert_eq!(View::Top.for_set(&rest), View::Top);
        assert_eq!(View::Auto.for_set(&[]), View::Auto);

        // Seen from the left (z to the right, y up): 1.6 wide, 0.6 high.
        assert_eq!(bent.fit(View::Left, 160), (160, 60));
        // From the front the same box is 0.2 wide and 0.6 high: a tall picture.
        assert_eq!(bent.fit(View::Front, 150), (50, 150));
        // A needle keeps a quarter of the size; a point, a square.
        let needle = Bounds {
            min: [0.0, 0.0, -1.0],
            max: [0.0, 0.001, 1.0],
        };
        assert_eq!(needle.fit(View::Left, 160), (160, 40));
        let point = Bounds {
            min: [1.0; 3],
            max: [1.0; 3],
        };
        assert_eq!(point.fit(View::Front, 64), (64, 64));
        // The fitted picture frames the box with the margin on both axes.
        let (w, h) = bent.fit(View::Left, 160);
        let p = Projection::new(View::Left, &bent, w, h);
        let top = p.project([0.0, 0.5, 0.0])[1];
        let left = p.project([0.0, 0.0, -0.8])[0];
        assert!((top - MARGIN * h as f32).abs() < 0.5, "{top}");
        assert!((left - MARGIN * w as f32).abs() < 0.5, "{left}");
    }

    #[test]
    fn bounds_are_the_union_of_finite_points() {
        let a = [[0.0, 1.0, 2.0], [f32::NAN, 9.0, 9.0]];
        let b = [[-1.0, 5.0, 0.0]];
        let bounds = Bounds::of(&[&a, &b]).unwrap();
        assert_eq!(bounds.min, [-1.0, 1.0, 0.0]);
        assert_eq!(bounds.max, [0.0, 5.0, 2.0]);
        assert!(Bounds::of(&[&[]]).is_none());
    }

    #[test]
    fn projection_centres_the_box_and_keeps_the_margin_on_the_limiting_axis() {
        let bounds = Bounds {
            min: [0.0, 0.0, 0.0],
            max: [2.0, 1.0, 0.0],
        };
        let p = Projection::new(View::Front, &bounds, 200, 200);
        let lo = p.project([0.0, 0.0, 0.0]);
        let hi = p.project([2.0, 1.0, 0.0]);
        assert!((lo[0] - 10.0).abs() < 1e-4 && (hi[0] - 190.0).abs() < 1e-4);
        // y grows downwards; the height is 90 px, centred.
        assert!((lo[1] - 145.0).abs() < 1e-4 && (hi[1] - 55.0).abs() < 1e-4);
    }
}
