//! Step 5 of the bake: the camera paths computed from the terrain and the wind scenes.

use glam::DVec2;

use crate::world::manifest::{
    CameraKey, CameraPath, DEFAULT_WIND_BLEND_S, WindDefaults, WindKey, WindScene, WindSource,
};

use super::paint::Painted;
use super::resample::Grid;
use super::round_to;

/// Height of the camera above the highest terrain near the overview path, metres.
const OVERVIEW_CLEARANCE_M: f64 = 220.0;
/// Height of the camera above the highest terrain near the low path, metres.
const LOW_CLEARANCE_M: f64 = 32.0;
/// Height of the meadow glide above the highest ground near it, metres.
const MEADOW_CLEARANCE_M: f64 = 2.0;

/// Name of the baked camera path that the `helicopter` wind scene's downwash follows.
pub const HELICOPTER_PATH: &str = "helicopter";

/// The wind scenes of a baked world, the ambient wind of each blowing toward 20 degrees (east-
/// north-east), as [`WindDefaults::default`]:
/// - `calm`: 0.8 m/s, hardly gusting;
/// - `breeze`: 4 m/s, gustiness 0.35 (the world's default wind);
/// - `storm`: 14 m/s, gustiness 0.8, with two directional gust sources that swell and fade on
///   periods of 17 s and 23 s (so together they repeat only every 391 s), slightly off the mean
///   direction;
/// - `helicopter`: light air (2 m/s, gustiness 0.3) and a rotor's downwash following the
///   `helicopter` camera path: an omni source (25 m/s outward, radius 30 m) and a vortex
///   (4 m/s clockwise swirl, radius 30 m), both spinning up over the first 2 s.
pub fn default_wind_scenes() -> Vec<WindScene> {
    let ambient = |speed_mps: f32, gustiness: f32| WindDefaults {
        direction_deg: 20.0,
        speed_mps,
        gustiness,
    };
    let gust = |direction_deg: f64, speed_mps: f64, period_s: f64| WindSource::Directional {
        direction_deg,
        speed_mps,
        position_m: None,
        path: None,
        start_s: 0.0,
        strength: [(0.0, 0.0), (0.35, 0.0), (0.55, 1.0), (0.7, 1.0), (1.0, 0.0)]
            .map(|(u, f)| [round_to(period_s * u, 2), f])
            .to_vec(),
        repeat: true,
    };
    let spin_up = vec![[0.0, 0.0], [2.0, 1.0]];
    vec![
        WindScene {
            name: "calm".into(),
            ambient: ambient(0.8, 0.15),
            sources: Vec::new(),
        },
        WindScene {
            name: "breeze".into(),
            ambient: ambient(4.0, 0.35),
            sources: Vec::new(),
        },
        WindScene {
            name: "storm".into(),
            ambient: ambient(14.0, 0.8),
            sources: vec![gust(35.0, 6.0, 17.0), gust(5.0, 5.0, 23.0)],
        },
        WindScene {
            name: "helicopter".into(),
            ambient: ambient(2.0, 0.3),
            sources: vec![
                WindSource::Omni {
                    radius_m: 30.0,
                    speed_mps: 25.0,
                    position_m: None,
                    path: Some(HELICOPTER_PATH.into()),
                    start_s: 0.0,
                    strength: spin_up.clone(),
                    repeat: false,
                },
                WindSource::Vortex {
                    radius_m: 30.0,
                    speed_mps: 4.0,
                    clockwise: true,
                    inflow_mps: 0.0,
                    position_m: None,
                    path: Some(HELICOPTER_PATH.into()),
                    start_s: 0.0,
                    strength: spin_up,
                    repeat: false,
                },
            ],
        },
    ]
}

/// The finest step, metres, at which a path's clearance is checked.
const MIN_CLEARANCE_STEP_M: f64 = 1.0;

/// The finest step, metres, of the search for the wind scenes' patch of tall grass: its
/// candidates and the samples around each. Fine DEMs (lidar at 0.5 m) would otherwise make the
/// search grow with the inverse fourth power of the cell (hours at 0.5 m).
const MIN_SPOT_STEP_M: f64 = 10.0;

/// Highest terrain within `half_width` of the polyline through `points`, sampled every `step`.
fn max_terrain_along(grid: &Grid, points: &[DVec2], half_width: f64, step: f64) -> f64 {
    let mut best = f64::NEG_INFINITY;
    for w in points.windows(2) {
        let (p, q) = (w[0], w[1]);
        let d = q - p;
        let len = d.length();
        let side = if len > 0.0 {
            d.perp() / len
        } else {
            DVec2::ZERO
        };
        let n = (len / step).ceil().max(1.0) as usize;
        for s in 0..=n {
            let c = p + d * (s as f64 / n as f64);
            for o in [-1.0, -0.5, 0.0, 0.5, 1.0] {
                best = best.max(grid.height(c + side * (o * half_width)));
            }
        }
    }
    best
}

/// Keys along `points` (one per key time): each key's height clears the highest terrain near
/// the path on both sides of it by `clearance`, so the straight line between two keys clears
/// the terrain under it by at least `clearance` too.
fn keys_along(
    grid: &Grid,
    extent: [f64; 2],
    points: &[DVec2],
    times: &[f64],
    clearance: f64,
    half_width: f64,
    pitch_deg: f64,
) -> Vec<CameraKey> {
    // Over the data area: a world smaller or narrower than a path's design (a strip of DEM, a
    // few cells) still gets its keys above its own ground, not over nothing.
    let e = DVec2::from(extent);
    let points: Vec<DVec2> = points.iter().map(|p| p.clamp(DVec2::ZERO, e)).collect();
    let points = points.as_slice();
    let last = points.len() - 1;
    let mut keys: Vec<CameraKey> = Vec::with_capacity(points.len());
    for k in 0..=last {
        let around = &points[k.saturating_sub(1)..=(k + 1).min(last)];
        // Half a cell, but no finer than a metre: a lidar DEM's 10 cm cells would otherwise
        // take millions of samples a key for a clearance of metres.
        let step = (grid.spacing() * 0.5).max(MIN_CLEARANCE_STEP_M);
        let z = max_terrain_along(grid, around, half_width, step) + clearance;
        let ahead = points[(k + 1).min(last)] - points[k.saturating_sub(1)];
        let mut yaw = ahead.y.atan2(ahead.x).to_degrees();
        if let Some(prev) = keys.last() {
            // Unwrap, so that interpolating yaw never turns the long way round.
            yaw = prev.yaw_deg + (yaw - prev.yaw_deg + 540.0).rem_euclid(360.0) - 180.0;
        }
        keys.push(CameraKey {
            t_s: times[k],
            position_m: [
                round_to(points[k].x, 2),
                round_to(points[k].y, 2),
                round_to(z, 2),
            ],
            yaw_deg: round_to(yaw, 3),
            pitch_deg,
        });
    }
    keys
}
/// A 60 s flight along a gentle S-curve from the south-west to the north-east of the data
/// area, high above the terrain, looking ahead and down.
pub(super) fn overview_path(painted: &Painted, extent: [f64; 2]) -> CameraPath {
    let grid = &painted.grid;
    let e = DVec2::from(extent);
    let a = e * DVec2::new(0.12, 0.10);
    let b = e * DVec2::new(0.88, 0.90);
    let d = b - a;
    let side = d.perp().normalize_or_zero() * (0.07 * d.length());
    const DURATION: f64 = 60.0;
    const KEYS: usize = 31;
    let times: Vec<f64> = (0..KEYS)
        .map(|k| DURATION * k as f64 / (KEYS - 1) as f64)
        .collect();
    let points: Vec<DVec2> = times
        .iter()
        .map(|t| {
            let u = t / DURATION;
            a + d * u + side * (std::f64::consts::TAU * u).sin()
        })
        .collect();
    CameraPath::through(
        "overview",
        keys_along(
            grid,
            extent,
            &points,
            &times,
            OVERVIEW_CLEARANCE_M,
            150.0,
            -14.0,
        ),
    )
}

/// The grassiest, gentlest 1.6 km line of the data area: its centre and its direction, heading
/// toward the higher ground.
fn grassy_line(painted: &Painted, extent: [f64; 2]) -> (DVec2, DVec2) {
    let grid = &painted.grid;
    const LENGTH: f64 = 1600.0;
    let e = DVec2::from(extent);
    let density_at = |p: DVec2| f64::from(painted.density[painted.index_at(p)]) / 255.0;
    // Candidates: centres on a grid inside the data area, eight headings each. Score: grass
    // cover along the line, less its height variation (a low pass over rugged ground would
    // either hit hills or fly high over valleys).
    let inset = (LENGTH * 0.6).min(e.min_element() * 0.45);
    let steps = 24;
    let mut best = (f64::NEG_INFINITY, e * 0.5, DVec2::X);
    for cy in 0..=steps {
        if painted.cancelled() {
            break;
        }
        for cx in 0..=steps {
            let c = DVec2::new(
                inset + (e.x - 2.0 * inset) * cx as f64 / steps as f64,
                inset + (e.y - 2.0 * inset) * cy as f64 / steps as f64,
            );
            for h in 0..8 {
                let dir = DVec2::from_angle(std::f64::consts::PI * h as f64 / 8.0);
                let (mut cover, mut lo, mut hi) = (0.0, f64::INFINITY, f64::NEG_INFINITY);
                let n = 32;
                for s in 0..=n {
                    let p = c + dir * LENGTH * (s as f64 / n as f64 - 0.5);
                    cover += density_at(p);
                    let z = grid.height(p);
                    lo = lo.min(z);
                    hi = hi.max(z);
                }
                let score = cover / (n + 1) as f64 - (hi - lo) / 100.0;
                if score > best.0 {
                    best = (score, c, dir);
                }
            }
        }
    }
    let (_, c, mut dir) = best;
    // Fly toward the higher ground, so that the view ahead holds hills rather than plain.
    if grid.height(c - dir * 3000.0) > grid.height(c + dir * 3000.0) {
        dir = -dir;
    }
    (c, dir)
}

/// A 32 s pass 30-60 m above the ground along the grassy line, toward the higher ground.
pub(super) fn low_path(painted: &Painted, extent: [f64; 2]) -> CameraPath {
    const LENGTH: f64 = 1600.0;
    const DURATION: f64 = 32.0;
    const KEYS: usize = 33;
    let grid = &painted.grid;
    let (c, dir) = grassy_line(painted, extent);
    let times: Vec<f64> = (0..KEYS)
        .map(|k| DURATION * k as f64 / (KEYS - 1) as f64)
        .collect();
    let points: Vec<DVec2> = times
        .iter()
        .map(|t| c + dir * LENGTH * (t / DURATION - 0.5))
        .collect();
    CameraPath::through(
        "low",
        keys_along(grid, extent, &points, &times, LOW_CLEARANCE_M, 20.0, -8.0),
    )
}

/// The tour, the default path: 30 s descending from high above the highest ground near the
/// meadow of the grassy line toward it, then 20 s gliding a couple of metres above it at
/// 8 m/s: terrain far and grass near in one flight.
pub(super) fn tour_path(painted: &Painted, extent: [f64; 2]) -> CameraPath {
    const APPROACH_S: f64 = 30.0;
    const GLIDE_S: f64 = 20.0;
    const GLIDE_SPEED: f64 = 8.0;
    const KEYS_A_SECOND: f64 = 1.0;
    let grid = &painted.grid;
    let e = DVec2::from(extent);
    let (c, dir) = grassy_line(painted, extent);
    let glide = GLIDE_SPEED * GLIDE_S;
    let meadow_start = c - dir * (glide / 2.0);
    // Start over the highest ground 2 to 8 km from the meadow (inside the data area), so that
    // the first half of the flight shows ridges and valleys from the air; where the world has
    // no such ground, 2.5 km back along the line. The approach is a quadratic Bezier curve that
    // comes into the meadow along the line.
    let inside =
        |a: DVec2| a.x > 0.05 * e.x && a.y > 0.05 * e.y && a.x < 0.95 * e.x && a.y < 0.95 * e.y;
    let mut start = None;
    let mut best = f64::NEG_INFINITY;
    let step = 200.0;
    let n = (8000.0 / step) as i64;
    for j in -n..=n {
        for i in -n..=n {
            let p = meadow_start + DVec2::new(i as f64, j as f64) * step;
            let r = p.distance(meadow_start);
            if !(2000.0..=8000.0).contains(&r) || !inside(p) {
                continue;
            }
            let h = grid.height(p);
            if h > best {
                best = h;
                start = Some(p);
            }
        }
    }
    let meadow_h = grid.height(meadow_start);
    let start = match start {
        Some(p) if best > meadow_h + 100.0 => p,
        _ => {
            let mut back = 2500.0;
            while back > 200.0 && !inside(meadow_start - dir * back) {
                back *= 0.8;
            }
            meadow_start - dir * back
        }
    };
    let span = start.distance(meadow_start);
    let control = meadow_start - dir * (0.45 * span);
    let curve = |v: f64| {
        let w = 1.0 - v;
        start * (w * w) + control * (2.0 * w * v) + meadow_start * (v * v)
    };
    // The curve's length, for the speeds below.
    let back: f64 = (0..64)
        .map(|k| curve((k + 1) as f64 / 64.0).distance(curve(k as f64 / 64.0)))
        .sum();
    // Distance along the approach: cubic Hermite from 1.5 times the mean speed down to the
    // glide's speed, so the camera slows smoothly into the glide.
    let (v0, v1) = (1.5 * back / APPROACH_S, GLIDE_SPEED);
    let along = |u: f64| {
        let (u2, u3) = (u * u, u * u * u);
        (u3 - 2.0 * u2 + u) * APPROACH_S * v0
            + (-2.0 * u3 + 3.0 * u2) * back
            + (u3 - u2) * APPROACH_S * v1
    };
    let n_approach = (APPROACH_S * KEYS_A_SECOND) as usize;
    let n_glide = (GLIDE_S * KEYS_A_SECOND) as usize;
    let mut times = Vec::new();
    let mut points = Vec::new();
    let mut clearance = Vec::new();
    let mut pitch = Vec::new();
    for k in 0..n_approach {
        let u = k as f64 / n_approach as f64;
        times.push(APPROACH_S * u);
        points.push(curve((along(u) / back).clamp(0.0, 1.0)));
        let high = (1.0 - u) * (1.0 - u);
        clearance.push(MEADOW_CLEARANCE_M + (OVERVIEW_CLEARANCE_M - MEADOW_CLEARANCE_M) * high);
        pitch.push(-6.0 - 14.0 * high);
    }
    for k in 0..=n_glide {
        let u = k as f64 / n_glide as f64;
        times.push(APPROACH_S + GLIDE_S * u);
        points.push(meadow_start + dir * (glide * u));
        clearance.push(MEADOW_CLEARANCE_M);
        pitch.push(-6.0);
    }
    let mut keys = keys_along(grid, extent, &points, &times, 0.0, 2.0, 0.0);
    for (k, key) in keys.iter_mut().enumerate() {
        key.position_m[2] = round_to(key.position_m[2] + clearance[k], 2);
        key.pitch_deg = round_to(pitch[k], 2);
    }
    CameraPath::through("tour", keys)
}

/// A 24 s glide at 8 m/s a couple of metres above the meadow in the middle of the grassy line:
/// the view for grass.
pub(super) fn meadow_path(painted: &Painted, extent: [f64; 2]) -> CameraPath {
    const LENGTH: f64 = 192.0;
    const DURATION: f64 = 24.0;
    const KEYS: usize = 25;
    let grid = &painted.grid;
    let (c, dir) = grassy_line(painted, extent);
    let times: Vec<f64> = (0..KEYS)
        .map(|k| DURATION * k as f64 / (KEYS - 1) as f64)
        .collect();
    let points: Vec<DVec2> = times
        .iter()
        .map(|t| c + dir * LENGTH * (t / DURATION - 0.5))
        .collect();
    CameraPath::through(
        "meadow",
        keys_along(grid, extent, &points, &times, MEADOW_CLEARANCE_M, 2.0, -6.0),
    )
}

/// The middle and direction of the helicopter's pass: the tall-grass spot nearest the middle
/// of the grassy line, along that line.
fn helicopter_line(painted: &Painted, extent: [f64; 2]) -> (DVec2, DVec2) {
    let (c, dir) = grassy_line(painted, extent);
    (tall_grass_spot(painted, extent, c), dir)
}

/// The point within 2 km of `near` (and at least 80 m inside the data area) whose surroundings
/// (40 m around) are most thoroughly tall grass, dense and level, nearest `near` among equals.
/// Wind reads best on tall blades.
fn tall_grass_spot(painted: &Painted, extent: [f64; 2], near: DVec2) -> DVec2 {
    const REACH_M: f64 = 2000.0;
    const AROUND_M: f64 = 40.0;
    let grid = &painted.grid;
    let e = DVec2::from(extent);
    let inset = DVec2::splat(80.0).min(e * 0.45);
    let inside = |p: DVec2| p.cmpge(inset).all() && p.cmple(e - inset).all();
    let sample = |p: DVec2| -> (u8, f64) {
        let i = painted.index_at(p);
        (painted.grass_type[i], f64::from(painted.density[i]) / 255.0)
    };
    let step = grid.spacing().max(MIN_SPOT_STEP_M);
    let steps = (REACH_M / step).round() as i64;
    let ring = (AROUND_M / step).ceil() as i64;
    let mut best = (
        f64::NEG_INFINITY,
        f64::INFINITY,
        near.clamp(inset, e - inset),
    );
    for j in -steps..=steps {
        if painted.cancelled() {
            break;
        }
        for i in -steps..=steps {
            let p = near + DVec2::new(i as f64, j as f64) * step;
            if !inside(p) {
                continue;
            }
            let (mut score, mut lo, mut hi) = (0.0, f64::INFINITY, f64::NEG_INFINITY);
            let mut count = 0.0;
            for b in -ring..=ring {
                for a in -ring..=ring {
                    let q = p + DVec2::new(a as f64, b as f64) * step;
                    if q.distance(p) > AROUND_M {
                        continue;
                    }
                    let (kind, density) = sample(q);
                    if kind == 2 {
                        score += density;
                    }
                    let z = grid.height(q);
                    (lo, hi) = (lo.min(z), hi.max(z));
                    count += 1.0;
                }
            }
            let score = score / count - (hi - lo) / 40.0;
            let distance = p.distance(near);
            if score > best.0 + 1e-9 || (score > best.0 - 1e-9 && distance < best.1) {
                best = (score, distance, p);
            }
        }
    }
    best.2
}

/// Height of the helicopter above the highest ground near its pass, metres.
const HELICOPTER_CLEARANCE_M: f64 = 16.0;

/// A 20 s pass at 5 m/s, 16 m above the highest ground near it, over the tall grass nearest
/// the middle of the grassy line, along that line, looking ahead and down: the helicopter that
/// the `helicopter` wind scene's downwash follows.
pub(super) fn helicopter_path(painted: &Painted, extent: [f64; 2]) -> CameraPath {
    const LENGTH: f64 = 100.0;
    const DURATION: f64 = 20.0;
    const KEYS: usize = 11;
    let grid = &painted.grid;
    let (c, dir) = helicopter_line(painted, extent);
    let times: Vec<f64> = (0..KEYS)
        .map(|k| DURATION * k as f64 / (KEYS - 1) as f64)
        .collect();
    let points: Vec<DVec2> = times
        .iter()
        .map(|t| c + dir * LENGTH * (t / DURATION - 0.5))
        .collect();
    CameraPath::through(
        HELICOPTER_PATH,
        keys_along(
            grid,
            extent,
            &points,
            &times,
            HELICOPTER_CLEARANCE_M,
            5.0,
            -30.0,
        ),
    )
}

/// Name of the baked fly-through that shows the wind scenes in turn.
pub const WIND_TOUR_PATH: &str = "wind-tour";
/// Name of the baked path of the walker whose trail the wind tour shows.
pub const WALKER_PATH: &str = "walker";
/// The wind tour's scenes and the times they start, seconds: each holds 12 s (the helicopter
/// 14 s, for its pass to cross the view), blending in over [`DEFAULT_WIND_BLEND_S`].
pub const WIND_TOUR_SCENES: [(&str, f64); 4] = [
    ("calm", 0.0),
    ("breeze", 12.0),
    ("storm", 24.0),
    ("helicopter", 36.0),
];
/// Length of the wind tour, seconds.
const WIND_TOUR_S: f64 = 50.0;

/// The wind tour and its walker. The camera stands 6 m above a patch of tall grass near the
/// grassy line (see [`tall_grass_spot`]), 18 m to the side of the helicopter's pass and looking
/// down across it (to the right of the pass's direction, so that for the baked world the sun is
/// behind the camera and bent blades catch it), and drifts 6 m along it over 50 s; the wind changes from calm to breeze to
/// storm to the helicopter scene (whose pass crosses the middle of the view about 10 s into it).
/// A walker circles 11 m in front of the camera (4 m radius, 1.25 m/s), leaving its trail in the
/// grass in every scene.
pub(super) fn wind_tour_paths(painted: &Painted, extent: [f64; 2]) -> (CameraPath, CameraPath) {
    const SIDE_M: f64 = 18.0;
    const DRIFT_M: f64 = 6.0;
    const CLEARANCE_M: f64 = 6.0;
    const WALK_SIDE_M: f64 = 7.0;
    const WALK_RADIUS_M: f64 = 4.0;
    const WALK_SPEED: f64 = 1.25;
    let grid = &painted.grid;
    let (c, dir) = helicopter_line(painted, extent);
    let side = -dir.perp();
    let look = -side;
    let yaw = round_to(look.y.atan2(look.x).to_degrees(), 3);
    let keys_n = WIND_TOUR_S as usize;
    let times: Vec<f64> = (0..=keys_n).map(|k| k as f64).collect();
    let camera_points: Vec<DVec2> = times
        .iter()
        .map(|t| c + side * SIDE_M + dir * (DRIFT_M * (t / WIND_TOUR_S - 0.5)))
        .collect();
    let mut keys = keys_along(
        grid,
        extent,
        &camera_points,
        &times,
        CLEARANCE_M,
        1.0,
        -24.0,
    );
    for k in &mut keys {
        k.yaw_deg = yaw;
    }
    let centre = c + side * WALK_SIDE_M;
    let omega = WALK_SPEED / WALK_RADIUS_M;
    let walk_points: Vec<DVec2> = times
        .iter()
        .map(|t| centre + DVec2::from_angle(omega * t) * WALK_RADIUS_M)
        .collect();
    let walker = CameraPath::through(
        WALKER_PATH,
        keys_along(grid, extent, &walk_points, &times, 1.7, 0.0, 0.0),
    );
    let tour = CameraPath {
        walker: Some(WALKER_PATH.into()),
        wind: WIND_TOUR_SCENES
            .iter()
            .map(|&(scene, t_s)| WindKey {
                t_s,
                scene: scene.into(),
                blend_s: DEFAULT_WIND_BLEND_S,
            })
            .collect(),
        ..CameraPath::through(WIND_TOUR_PATH, keys)
    };
    (tour, walker)
}
