//! The steering formulas of the Robots crowd system (Patterson 2005), as pure
//! functions on the ground plane. See docs/sim.md for how they combine.
//!
//! Ground-plane vectors are `Vec2(x, z)`: `.x` is world X, `.y` is world Z.
//! Headings are radians about +Y, 0 faces +Z, positive turns counter-clockwise
//! seen from above, which for a walking agent is a turn to its LEFT
//! (heading pi/2 faces +X; an agent facing +Z has -X on its right).

use glam::Vec2;

use super::Model;

/// The paper's distance fall-off, `D(d) = 1 / 2^d`.
pub(crate) fn falloff(d: f32) -> f32 {
    (-d).exp2()
}

/// The paper's angular repulsion, `((1 + cos a) / 2)^2`: 1 for an object
/// straight ahead, 0.25 at 90 degrees, 0 behind.
pub(crate) fn repulsion(cos_a: f32) -> f32 {
    let t = (1.0 + cos_a.clamp(-1.0, 1.0)) * 0.5;
    t * t
}

/// Attenuation of another agent's influence by "chase", the dot product of
/// the two normalised velocities: agents walking the same way (chase > 0)
/// push less, by `1 - chase`, so a file of walkers does not shake.
pub(crate) fn chase_attenuation(chase: f32) -> f32 {
    if chase > 0.0 {
        1.0 - chase.min(1.0)
    } else {
        1.0
    }
}

/// The largest turn this frame (radians): `max_turn`, relaxed near objects
/// to `max_turn * (1 + (relax - d)^2)` when the nearest object's gap `d`
/// (metres) is under `relax` (the paper's 5 units): 25 degrees at 3 m, 50 at 2 m.
pub fn turn_limit(max_turn: f32, relax: f32, d: f32) -> f32 {
    if d < relax {
        let k = relax - d.max(0.0);
        max_turn * (1.0 + k * k)
    } else {
        max_turn
    }
}

/// Unit facing direction of `heading` on the ground plane.
pub(crate) fn forward(heading: f32) -> Vec2 {
    let (s, c) = heading.sin_cos();
    Vec2::new(s, c)
}

/// Heading that faces along `dir` (inverse of [`forward`]).
pub(crate) fn heading_of(dir: Vec2) -> f32 {
    dir.x.atan2(dir.y)
}

/// Wraps an angle into (-pi, pi].
pub fn wrap_angle(a: f32) -> f32 {
    use std::f32::consts::{PI, TAU};
    let w = (a + PI).rem_euclid(TAU) - PI;
    if w <= -PI {
        w + TAU
    } else {
        w
    }
}

/// Which way an object makes the agent turn, from the sign of the cross
/// product of the facing and the vector to the object: +1 (turn left,
/// counter-clockwise) for an object on the right, -1 for one on the left.
/// An object dead ahead turns the agent left, so two agents meeting head on
/// both veer left and pass.
pub(crate) fn turn_side(forward: Vec2, to_object: Vec2) -> f32 {
    // Y component of (forward x to) in 3D with (x, 0, z) vectors: positive
    // when the object is counter-clockwise from the facing, i.e. on the left.
    let cross_y = forward.y * to_object.x - forward.x * to_object.y;
    if cross_y > 0.0 {
        -1.0
    } else {
        1.0
    }
}

/// Influences gathered for one agent in one frame.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Steer {
    /// Signed sum of weighted repulsions (positive turns left).
    pub(crate) sum: f32,
    /// Strongest slow-down cue in [0, 1].
    pub(crate) slow: f32,
    /// Smallest gap (metres) to any object this agent heeds.
    pub(crate) nearest: f32,
}

impl Default for Steer {
    fn default() -> Self {
        Steer { sum: 0.0, slow: 0.0, nearest: f32::INFINITY }
    }
}

impl Steer {
    /// Adds one repelling object: `to` runs from the agent to the object's
    /// closest point, `gap` is the surface-to-surface distance in metres,
    /// `weight` the agent's handle for this kind of object, `atten` the
    /// chase attenuation (1 for obstacles and walls).
    pub(crate) fn add(&mut self, model: &Model, fwd: Vec2, to: Vec2, gap: f32, weight: f32, atten: f32) {
        if weight == 0.0 {
            return; // a blind agent does not see this kind of object at all
        }
        let len = to.length();
        // An object on top of the agent counts as dead ahead.
        let (cos_a, side) = if len > 1e-6 { (fwd.dot(to / len), turn_side(fwd, to)) } else { (1.0, 1.0) };
        let r = repulsion(cos_a);
        let d = gap.max(0.0) / model.falloff;
        let strength = falloff(d * model.power); // D(d)^power
        self.sum += side * weight * strength * r * atten;
        self.slow = self.slow.max((r * atten * falloff(d)).min(1.0));
        self.nearest = self.nearest.min(gap.max(0.0));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f32::consts::{FRAC_PI_2, PI};

    #[test]
    fn paper_values() {
        assert_eq!(falloff(0.0), 1.0);
        assert_eq!(falloff(1.0), 0.5);
        assert_eq!(falloff(3.0), 0.125);
        assert!((repulsion(1.0) - 1.0).abs() < 1e-6);
        assert!((repulsion(0.0) - 0.25).abs() < 1e-6);
        assert!(repulsion(-1.0).abs() < 1e-6);
        assert_eq!(chase_attenuation(1.0), 0.0);
        assert_eq!(chase_attenuation(0.25), 0.75);
        assert_eq!(chase_attenuation(-0.5), 1.0);
        let deg = |d: f32| d.to_radians();
        assert!((turn_limit(deg(5.0), 5.0, 3.0) - deg(25.0)).abs() < 1e-5);
        assert!((turn_limit(deg(5.0), 5.0, 2.0) - deg(50.0)).abs() < 1e-5);
        assert_eq!(turn_limit(deg(5.0), 5.0, 7.0), deg(5.0));
        assert_eq!(turn_limit(deg(5.0), 5.0, f32::INFINITY), deg(5.0));
    }

    #[test]
    fn heading_convention() {
        // Heading 0 faces +Z, pi/2 faces +X.
        assert!(forward(0.0).abs_diff_eq(Vec2::new(0.0, 1.0), 1e-6));
        assert!(forward(FRAC_PI_2).abs_diff_eq(Vec2::new(1.0, 0.0), 1e-6));
        assert!((heading_of(Vec2::new(1.0, 0.0)) - FRAC_PI_2).abs() < 1e-6);
        assert!((wrap_angle(3.0 * PI) - PI).abs() < 1e-5);
        assert!((wrap_angle(-PI) - PI).abs() < 1e-5);
        assert!((wrap_angle(0.5) - 0.5).abs() < 1e-6);
    }

    #[test]
    fn right_side_turns_left() {
        let f = forward(0.0); // facing +Z: the agent's right is -X
        assert_eq!(turn_side(f, Vec2::new(-1.0, 1.0)), 1.0, "object ahead-right turns the agent left (+)");
        assert_eq!(turn_side(f, Vec2::new(1.0, 1.0)), -1.0, "object ahead-left turns the agent right (-)");
        // Turning left (+) from heading 0 faces towards +X, away from the object at -X.
        assert!(forward(0.1).x > 0.0);
    }

    #[test]
    fn steep_falloff_and_weights() {
        let m = Model::default();
        let mut s = Steer::default();
        s.add(&m, forward(0.0), Vec2::new(-0.1, 1.0), 0.25, 1.0, 1.0);
        let near = s.sum;
        let mut t = Steer::default();
        t.add(&m, forward(0.0), Vec2::new(-0.1, 1.0), 1.0, 1.0, 1.0);
        assert!(near > 0.0 && t.sum > 0.0);
        assert!(near / t.sum > 400.0, "D^12 falls 2^-9 between 0.25 and 1 m");
        let mut blind = Steer::default();
        blind.add(&m, forward(0.0), Vec2::new(-0.1, 1.0), 0.25, 0.0, 1.0);
        assert_eq!(blind.sum, 0.0);
        assert_eq!(blind.nearest, f32::INFINITY);
    }
}
