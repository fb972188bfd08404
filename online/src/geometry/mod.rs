//! Obstacles in the planner's position space, of two or three axes: [`plane`] holds the planar ones (circles,
//! rectangles, walls), [`space`] the solids (spheres, boxes, pillars, floor and ceiling). Every kind answers
//! [`Obstacle`]: exact distances from points and segments, so that inflation by a bound and line-of-sight
//! checks are exact rather than sampled. The online loop, the raw-path planners and the simulator take the
//! dimension `D` and an obstacle kind of that dimension.

pub mod plane;
pub mod space;

pub use plane::PlaneObstacle;
pub use space::SpaceObstacle;

use std::fmt::Debug;

/// A point in the planner's position coordinates (m), `D` axes: `[x, y]` or `[x, y, z]`.
pub type Point<const D: usize = 2> = [f64; D];

/// An obstacle that cannot exist: what is wrong with it.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct ObstacleError(pub String);

/// What the loop and the planners ask of an obstacle in a `D`-axis space.
///
/// [`Obstacle::distance`] must be a distance to a set (so 1-Lipschitz: [`segment_is_free`] passes an obstacle
/// far from a segment's midpoint by it), and a kind that is not convex must answer
/// [`Obstacle::segment_distance`] itself.
pub trait Obstacle<const D: usize>: Debug + Clone + PartialEq + Send + Sync {
    /// Checks that every number is finite and every size positive.
    fn validate(&self) -> Result<(), ObstacleError>;

    /// Distance from `p` to the obstacle (0 inside it).
    fn distance(&self, p: Point<D>) -> f64;

    /// Distance from the segment `a`-`b` to the obstacle (0 if they touch). The default minimizes
    /// [`Obstacle::distance`] along the segment, which is convex there for a convex obstacle.
    fn segment_distance(&self, a: Point<D>, b: Point<D>) -> f64 {
        convex_segment_minimum(|p| self.distance(p), a, b)
    }
}

/// Golden-section steps of [`convex_segment_minimum`]: the bracket ends below `0.618^64 ~ 4e-14` of the
/// segment; the parameter's own resolution (about `1e-16`) limits it from there on.
const GOLDEN_SECTION_STEPS: usize = 64;

/// The minimum of a convex function of the point along the segment `a`-`b`, by golden-section search over
/// the segment's parameter (distance to a convex set is convex along a line and 1-Lipschitz, so the minimum
/// found exceeds the true one by at most about `4e-14 |b - a|`).
pub fn convex_segment_minimum<const D: usize>(f: impl Fn(Point<D>) -> f64, a: Point<D>, b: Point<D>) -> f64 {
    let at = |t: f64| f(lerp(a, b, t));
    let ratio = (5f64.sqrt() - 1.0) / 2.0;
    let (mut lo, mut hi) = (0.0, 1.0);
    let (mut left, mut right) = (hi - ratio * (hi - lo), lo + ratio * (hi - lo));
    let (mut f_left, mut f_right) = (at(left), at(right));
    for _ in 0..GOLDEN_SECTION_STEPS {
        if f_left <= f_right {
            hi = right;
            (right, f_right) = (left, f_left);
            left = hi - ratio * (hi - lo);
            f_left = at(left);
        } else {
            lo = left;
            (left, f_left) = (right, f_right);
            right = lo + ratio * (hi - lo);
            f_right = at(right);
        }
    }
    f_left.min(f_right).min(at(0.0)).min(at(1.0))
}

/// Adds to `known` the obstacles of `sensed` it does not hold yet; true if there were any (an obstacle is
/// newly sensed).
pub fn remember<O: Obstacle<D>, const D: usize>(known: &mut Vec<O>, sensed: &[O]) -> bool {
    let before = known.len();
    for obstacle in sensed {
        if !known.contains(obstacle) {
            known.push(obstacle.clone());
        }
    }
    known.len() > before
}

/// The smallest distance from `p` to any of `obstacles` (infinite for none).
pub fn clearance<O: Obstacle<D>, const D: usize>(obstacles: &[O], p: Point<D>) -> f64 {
    obstacles.iter().map(|o| o.distance(p)).fold(f64::INFINITY, f64::min)
}

/// Round-off allowed for in [`segment_is_free`]'s midpoint test (m): a segment that only touches the inflated
/// obstacle must not pass it by a rounding error.
const MIDPOINT_TEST_MARGIN: f64 = 1e-9;

/// True if the segment `a`-`b` keeps more than `inflation` from every obstacle. An obstacle clearly farther
/// than `inflation` plus half the segment's length from its midpoint is passed without measuring the segment.
pub fn segment_is_free<O: Obstacle<D>, const D: usize>(
    obstacles: &[O],
    a: Point<D>,
    b: Point<D>,
    inflation: f64,
) -> bool {
    let (middle, half) = (lerp(a, b, 0.5), norm(sub(b, a)) / 2.0);
    obstacles
        .iter()
        .all(|o| o.distance(middle) - half > inflation + MIDPOINT_TEST_MARGIN || o.segment_distance(a, b) > inflation)
}

/// True if `p` lies in the box `(lo, hi)`, edges included.
pub fn inside<const D: usize>(p: Point<D>, (lo, hi): (Point<D>, Point<D>)) -> bool {
    (0..D).all(|axis| p[axis] >= lo[axis] && p[axis] <= hi[axis])
}

/// `a - b`.
pub fn sub<const D: usize>(a: Point<D>, b: Point<D>) -> Point<D> {
    std::array::from_fn(|axis| a[axis] - b[axis])
}

/// `a + t (b - a)`.
pub fn lerp<const D: usize>(a: Point<D>, b: Point<D>, t: f64) -> Point<D> {
    std::array::from_fn(|axis| a[axis] + t * (b[axis] - a[axis]))
}

/// `a . b`.
pub fn dot<const D: usize>(a: Point<D>, b: Point<D>) -> f64 {
    (0..D).map(|axis| a[axis] * b[axis]).sum()
}

/// Euclidean norm: in the plane exactly `a[0].hypot(a[1])`, as the Python port computes it; in space the
/// square root of the sum of squares (`hypot`'s care for overflow costs a third of a 3-D replan, and
/// workspace coordinates never come near it).
pub fn norm<const D: usize>(a: Point<D>) -> f64 {
    if D == 2 {
        a[0].hypot(a[1])
    } else {
        a.iter().map(|x| x * x).sum::<f64>().sqrt()
    }
}

/// The largest axis displacement, `max_i |a_i|`: a planner bounded to `beta` per axis needs this over `beta`
/// seconds to move by `a`.
pub fn chebyshev_norm<const D: usize>(a: Point<D>) -> f64 {
    a.iter().fold(0.0, |m, x| m.max(x.abs()))
}

/// Distance from `p` to the segment `a`-`b`.
pub fn point_segment_distance<const D: usize>(p: Point<D>, a: Point<D>, b: Point<D>) -> f64 {
    let ab = sub(b, a);
    let length2 = dot(ab, ab);
    let t = if length2 > 0.0 { (dot(sub(p, a), ab) / length2).clamp(0.0, 1.0) } else { 0.0 };
    norm(sub(p, lerp(a, b, t)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_convex_minimum_matches_a_closed_form() {
        // Distance to the point (1, 2, 0.5) along the segment from the origin to (4, 0, 0): the foot of the
        // perpendicular at x = 1, distance hypot(2, 0.5).
        let target = [1.0, 2.0, 0.5];
        let found = convex_segment_minimum(|p| norm(sub(p, target)), [0.0; 3], [4.0, 0.0, 0.0]);
        assert!((found - 2f64.hypot(0.5)).abs() < 1e-12, "{found}");
        // A minimum at an end of the segment.
        let end = convex_segment_minimum(|p| norm(sub(p, target)), [2.0, 0.0, 0.0], [4.0, 0.0, 0.0]);
        assert!((end - (1.0f64 + 4.0 + 0.25).sqrt()).abs() < 1e-12, "{end}");
        assert!((point_segment_distance(target, [0.0; 3], [4.0, 0.0, 0.0]) - found).abs() < 1e-12);
    }

    #[test]
    fn vector_helpers_work_in_any_dimension() {
        assert_eq!(sub([3.0, 2.0, 1.0], [1.0, 1.0, 1.0]), [2.0, 1.0, 0.0]);
        assert_eq!(lerp([0.0, 0.0], [2.0, 4.0], 0.25), [0.5, 1.0]);
        assert!((norm([2.0, 3.0, 6.0]) - 7.0).abs() < 1e-15);
        assert_eq!(chebyshev_norm([0.5, -2.0, 1.0]), 2.0);
        assert!(inside([1.0, 1.0, 1.0], ([0.0; 3], [1.0; 3])) && !inside([1.0, 1.1, 1.0], ([0.0; 3], [1.0; 3])));
    }
}
