//! [`Manifest::validate`]: every number finite and within the range its field documents, with
//! the field and the range named in the error.

use std::collections::HashSet;
use std::path::Path;

use super::*;

impl Manifest {
    /// Checks that every value is finite and within what the format supports, and that no text
    /// holds a control character ([`forbidden_control`]); `path` is only used in error
    /// messages.
    pub fn validate(&self, path: &Path) -> Result<(), WorldError> {
        let v = Validator { path };
        let p = &self.pyramid;
        // Checked here, not only when parsing, so that a bake refuses what its own loader would.
        if let Some((field, c)) = control_character(self) {
            return Err(v.out_of_range(
                &field,
                format!(
                    "a text holding the control character U+{:04X}",
                    u32::from(c)
                ),
                "text without control characters (tabs and line breaks aside) or characters \
                 that reorder the text around them: a world's names are printed to terminals \
                 and window titles",
            ));
        }
        if let Some((field, chars)) = overlong_name(self) {
            return Err(v.out_of_range(
                &field,
                format!("a name of {chars} characters"),
                &format!(
                    "at most {MAX_NAME_CHARS} characters: a world's names are printed in lines \
                     and window titles"
                ),
            ));
        }

        if let Some(id) = &self.bake_id
            && (id.len() != 16 || !id.bytes().all(|b| matches!(b, b'0'..=b'9' | b'a'..=b'f')))
        {
            return Err(v.out_of_range(
                "bake_id",
                format!("{id:?}"),
                "16 lowercase hexadecimal digits, as the baker writes it",
            ));
        }
        for axis in 0..2 {
            v.positive(&format!("extent_m[{axis}]"), self.extent_m[axis])?;
        }
        v.positive("pyramid.root_tile_size_m", p.root_tile_size_m)?;
        v.at_most(
            "pyramid.root_tile_size_m",
            p.root_tile_size_m,
            MAX_ROOT_TILE_M,
            " m",
        )?;
        for axis in 0..2 {
            if p.root_tiles[axis] == 0 {
                return Err(v.non_positive(&format!("pyramid.root_tiles[{axis}]"), 0.0));
            }
        }
        if !(8..=1024).contains(&p.tile_cells) || !p.tile_cells.is_power_of_two() {
            return Err(v.out_of_range(
                "pyramid.tile_cells",
                p.tile_cells,
                "a power of two in 8..=1024",
            ));
        }
        if p.border > 8 {
            return Err(v.out_of_range("pyramid.border", p.border, "in 0..=8"));
        }
        if !(1..=12).contains(&p.stored_levels) {
            return Err(v.out_of_range("pyramid.stored_levels", p.stored_levels, "in 1..=12"));
        }
        let levels = u32::from(p.stored_levels) + u32::from(p.derived_levels);
        if levels > 24 {
            return Err(v.out_of_range(
                "pyramid.stored_levels + pyramid.derived_levels",
                levels,
                "at most 24",
            ));
        }
        let roots = u64::from(p.root_tiles[0]) * u64::from(p.root_tiles[1]);
        if roots > MAX_ROOT_TILES {
            return Err(WorldError::TooManyTiles {
                path: path.to_path_buf(),
                field: "pyramid.root_tiles".into(),
                count: roots,
                max: MAX_ROOT_TILES,
            });
        }
        for axis in 0..2 {
            // Tile coordinates of the finest level, derived or stored, must fit a u32.
            if u64::from(p.root_tiles[axis]) << (levels - 1) > u64::from(u32::MAX) {
                return Err(v.out_of_range(
                    &format!("pyramid.root_tiles[{axis}]"),
                    p.root_tiles[axis],
                    "small enough that the finest level's tile count fits in 32 bits",
                ));
            }
        }
        let finest = roots << (2 * (u32::from(p.stored_levels) - 1));
        if finest > MAX_FINEST_TILES {
            return Err(WorldError::TooManyTiles {
                path: path.to_path_buf(),
                field: "pyramid.root_tiles and pyramid.stored_levels".into(),
                count: finest,
                max: MAX_FINEST_TILES,
            });
        }
        for axis in 0..2 {
            if self.extent_m[axis] > MAX_EXTENT_M {
                return Err(v.out_of_range(
                    &format!("extent_m[{axis}]"),
                    number(self.extent_m[axis]),
                    "at most 10,000 km (10000000 m)",
                ));
            }
            let grid_m = f64::from(p.root_tiles[axis]) * p.root_tile_size_m;
            // Allow rounding in the last digits of a value written out and read back.
            if self.extent_m[axis] > grid_m * (1.0 + 1e-9) {
                return Err(WorldError::ExtentBeyondGrid {
                    path: path.to_path_buf(),
                    axis,
                    extent_m: self.extent_m[axis],
                    grid_m,
                });
            }
        }

        v.grass_tiles(p)?;

        let [lo, hi] = self.height_range_m;
        v.finite("height_range_m[0]", lo)?;
        v.finite("height_range_m[1]", hi)?;
        if lo >= hi {
            return Err(WorldError::BadHeightRange {
                path: path.to_path_buf(),
                min: lo,
                max: hi,
            });
        }
        let [plo, phi] = crate::world::PLAUSIBLE_HEIGHTS_M;
        if f64::from(lo) < plo || f64::from(hi) > phi {
            return Err(v.out_of_range(
                "height_range_m",
                format!("[{}, {}]", number(f64::from(lo)), number(f64::from(hi))),
                &format!("within [{plo}, {phi}] m, the heights of a planet's surface"),
            ));
        }

        if self.grass_types.is_empty() {
            return Err(WorldError::NoGrassTypes {
                path: path.to_path_buf(),
            });
        }
        if self.grass_types.len() > MAX_GRASS_TYPES {
            return Err(v.out_of_range(
                "grass_types",
                format!("{} types", self.grass_types.len()),
                &format!(
                    "at most {MAX_GRASS_TYPES} types (the renderer draws {MAX_GRASS_TYPES} kinds \
                     of grass)"
                ),
            ));
        }
        v.non_empty_name("name", &self.name)?;
        // Plant types and cover tables name grass types: each name must say which.
        let mut grass_names = HashSet::new();
        for (index, g) in self.grass_types.iter().enumerate() {
            let field = |f: &str| format!("grass_types[{index}].{f}");
            v.non_empty_name(&field("name"), &g.name)?;
            if !grass_names.insert(g.name.as_str()) {
                return Err(v.out_of_range(
                    &field("name"),
                    &g.name,
                    "a name no other grass type has",
                ));
            }
            v.all_within(&field("ground_color"), &g.ground_color, [0.0, 1.0], "")?;
            v.all_within(&field("base_color"), &g.base_color, [0.0, 1.0], "")?;
            v.all_within(&field("tip_color"), &g.tip_color, [0.0, 1.0], "")?;
            v.all_finite(&field("height_m"), &g.height_m)?;
            v.all_finite(&field("width_m"), &g.width_m)?;
            v.within(&field("stiffness"), g.stiffness, [0.0, 1.0], "")?;
            for (name, [min, max], most) in [
                ("height_m", g.height_m, MAX_BLADE_HEIGHT_M),
                ("width_m", g.width_m, MAX_BLADE_WIDTH_M),
            ] {
                if min < 0.0 || min > max {
                    return Err(WorldError::BadGrassRange {
                        path: path.to_path_buf(),
                        index,
                        name: g.name.clone(),
                        field: name,
                        min,
                        max,
                    });
                }
                v.at_most(&format!("{}[1]", field(name)), max, most, " m")?;
            }
        }

        self.validate_plants(&v)?;
        v.validate_ambient("wind", &self.wind)?;
        let s = &self.sky;
        v.angle("sky.sun_azimuth_deg", s.sun_azimuth_deg)?;
        v.within(
            "sky.sun_elevation_deg",
            s.sun_elevation_deg,
            [-90.0, 90.0],
            " degrees",
        )?;
        v.all_within("sky.sun_color", &s.sun_color, [0.0, MAX_SUN_INTENSITY], "")?;
        v.all_within("sky.sky_color", &s.sky_color, [0.0, 1.0], "")?;
        v.all_within("sky.horizon_color", &s.horizon_color, [0.0, 1.0], "")?;
        v.positive("sky.fog_distance_m", s.fog_distance_m)?;
        v.at_most(
            "sky.fog_distance_m",
            s.fog_distance_m,
            MAX_FOG_DISTANCE_M,
            " m",
        )?;
        if let Some(source) = &self.source {
            for axis in 0..2 {
                let field = format!("source.cell_size_m[{axis}]");
                v.positive(&field, source.cell_size_m[axis])?;
                v.at_most(&field, source.cell_size_m[axis], MAX_EXTENT_M, " m")?;
            }
            if let Some(origin) = &source.origin {
                let most = MAX_SOURCE_COORDINATE;
                v.all_within("source.origin", origin, [-most, most], "")?;
            }
        }

        let mut names = HashSet::new();
        for (pi, cam) in self.paths.iter().enumerate() {
            v.non_empty_name(&format!("paths[{pi}].name"), &cam.name)?;
            if !names.insert(cam.name.as_str()) {
                return Err(WorldError::DuplicatePath {
                    path: path.to_path_buf(),
                    name: cam.name.clone(),
                });
            }
            let duration = format!("paths[{pi}].duration_s");
            v.positive(&duration, cam.duration_s)?;
            v.at_most(&duration, cam.duration_s, MAX_TIME_S, " s")?;
            if cam.keys.len() < 2 {
                return Err(WorldError::PathTooShort {
                    path: path.to_path_buf(),
                    name: cam.name.clone(),
                    field: format!("paths[{pi}].keys"),
                    keys: cam.keys.len(),
                });
            }
            for (ki, key) in cam.keys.iter().enumerate() {
                let field = |f: &str| format!("paths[{pi}].keys[{ki}].{f}");
                v.time(&field("t_s"), key.t_s)?;
                v.position(&field("position_m"), &key.position_m)?;
                v.angle(&field("yaw_deg"), key.yaw_deg)?;
                v.within(
                    &field("pitch_deg"),
                    key.pitch_deg,
                    [-90.0, 90.0],
                    " degrees",
                )?;
                if ki > 0 && key.t_s <= cam.keys[ki - 1].t_s {
                    return Err(WorldError::PathKeysOutOfOrder {
                        path: path.to_path_buf(),
                        name: cam.name.clone(),
                        field: field("t_s"),
                        index: ki,
                        t_s: key.t_s,
                        previous_t_s: cam.keys[ki - 1].t_s,
                    });
                }
            }
            // Every tool flies the keys' span: a duration that says otherwise would have one
            // tool fly a part of the path, or clamp to its last key, while another flies it all.
            let span_s = cam.length_s();
            if (cam.duration_s - span_s).abs() > PATH_DURATION_TOLERANCE_S {
                return Err(WorldError::PathDurationMismatch {
                    path: path.to_path_buf(),
                    name: cam.name.clone(),
                    field: duration,
                    duration_s: cam.duration_s,
                    span_s,
                    first_t_s: cam.start_s(),
                    last_t_s: cam.end_s(),
                });
            }
        }
        self.validate_wind_scenes(&v)?;
        for (pi, cam) in self.paths.iter().enumerate() {
            self.validate_path_wind(&v, pi, cam)?;
        }
        if let Some(g) = &self.grass_peak {
            v.positive("grass_peak.window_m", g.window_m)?;
            v.at_most("grass_peak.window_m", g.window_m, MAX_ROOT_TILE_M, " m")?;
            v.non_negative("grass_peak.short_m", g.short_m)?;
            v.at_most("grass_peak.short_m", g.short_m, MAX_BLADE_HEIGHT_M, " m")?;
            v.finite("grass_peak.density", g.density)?;
            if !(0.0..=2.0).contains(&g.density) {
                return Err(v.out_of_range(
                    "grass_peak.density",
                    number(f64::from(g.density)),
                    "in 0..=2",
                ));
            }
        }
        if let Some(c) = &self.derive {
            self.validate_derive(&v, c)?;
        }
        Ok(())
    }

    fn validate_plants(&self, v: &Validator) -> Result<(), WorldError> {
        if self.plant_types.len() > MAX_PLANT_TYPES {
            return Err(v.out_of_range(
                "plant_types",
                format!("{} types", self.plant_types.len()),
                &format!("at most {MAX_PLANT_TYPES} types"),
            ));
        }
        let mut names = HashSet::new();
        let mut per_grass = vec![0.0f64; self.grass_types.len()];
        for (index, p) in self.plant_types.iter().enumerate() {
            let field = |f: &str| format!("plant_types[{index}].{f}");
            v.non_empty_name(&field("name"), &p.name)?;
            if !names.insert(p.name.as_str()) {
                return Err(v.out_of_range(
                    &field("name"),
                    &p.name,
                    "a name no other plant type has",
                ));
            }
            let gltf = std::path::Path::new(&p.mesh)
                .extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("gltf") || e.eq_ignore_ascii_case("glb"));
            // A glTF file is named relative to the world's folder and stays inside it: the
            // same file on disk and over HTTP, and no name leads out of the world's folder.
            // A backslash is a separator on some servers and file systems: not in a name.
            let inside = std::path::Path::new(&p.mesh)
                .components()
                .all(|c| matches!(c, std::path::Component::Normal(_)))
                && !p.mesh.contains('\\');
            if gltf && !inside {
                return Err(v.out_of_range(
                    &field("mesh"),
                    &p.mesh,
                    "a .gltf or .glb file inside the world's folder, named relative to it \
                     with / between folders, without . or .. (plants/fern.gltf)",
                ));
            }
            if !PLANT_RECIPES.contains(&p.mesh.as_str()) && !gltf {
                return Err(v.out_of_range(
                    &field("mesh"),
                    &p.mesh,
                    &format!(
                        "one of {} or a .gltf or .glb file",
                        PLANT_RECIPES.join(", ")
                    ),
                ));
            }
            v.all_within(&field("color"), &p.color, [0.0, 1.0], "")?;
            let [lo, hi] = p.size_m;
            v.all_finite(&field("size_m"), &p.size_m)?;
            if !(lo.decimal() >= MIN_PLANT_SIZE_M && lo <= hi && hi.decimal() <= MAX_PLANT_SIZE_M) {
                return Err(v.out_of_range(
                    &field("size_m"),
                    format!("[{lo}, {hi}]"),
                    &format!("{MIN_PLANT_SIZE_M} m <= min <= max <= {MAX_PLANT_SIZE_M} m"),
                ));
            }
            for (grass, &d) in &p.density {
                let at = format!("{}.{grass}", field("density"));
                let Some(g) = self.grass_types.iter().position(|t| &t.name == grass) else {
                    let known: Vec<&str> =
                        self.grass_types.iter().map(|t| t.name.as_str()).collect();
                    return Err(v.out_of_range(
                        &at,
                        grass,
                        &format!("a grass type's name ({})", known.join(", ")),
                    ));
                };
                v.within(&at, d, [0.0, MAX_PLANT_DENSITY], " plants per m2")?;
                per_grass[g] += d.decimal();
            }
            v.within(
                &field("max_slope_deg"),
                p.max_slope_deg,
                [0.0, 90.0],
                " degrees",
            )?;
            v.all_finite(&field("altitude_m"), &p.altitude_m)?;
            if p.altitude_m[0] > p.altitude_m[1] {
                return Err(v.out_of_range(
                    &field("altitude_m"),
                    format!("{:?}", p.altitude_m),
                    "min <= max",
                ));
            }
            v.within(&field("clump_m"), p.clump_m, [1.0, 1000.0], " m")?;
            v.finite(&field("clump_cover"), p.clump_cover)?;
            if !(p.clump_cover > 0.0 && p.clump_cover <= 1.0) {
                return Err(v.out_of_range(&field("clump_cover"), p.clump_cover, "in (0, 1]"));
            }
            let w = &p.wind;
            let wf = |f: &str| format!("plant_types[{index}].wind.{f}");
            v.within(&wf("movement_scale"), w.movement_scale, [0.0, 4.0], "")?;
            v.within(&wf("bend"), w.bend, [0.0, 1.0], "")?;
            v.within(&wf("stretch"), w.stretch, [0.0, 1.0], "")?;
            v.within(&wf("stiffness"), w.stiffness, [0.0, 1.0], "")?;
            v.within(&wf("sway_spring_hz"), w.sway_spring_hz, [0.05, 10.0], " Hz")?;
            v.within(&wf("sway_damping"), w.sway_damping, [0.01, 2.0], "")?;
            v.within(&wf("main_amplitude"), w.main_amplitude, [0.0, 4.0], "")?;
            v.within(&wf("detail_amplitude"), w.detail_amplitude, [0.0, 4.0], "")?;
        }
        if let Some((g, &total)) = per_grass
            .iter()
            .enumerate()
            .find(|(_, d)| **d > MAX_PLANT_DENSITY)
        {
            return Err(v.out_of_range(
                &format!("plant_types[*].density.{}", self.grass_types[g].name),
                // The file's decimals added up, without the sum's rounding noise.
                format!(
                    "{} plants per m2 in all",
                    number((total * 1e6).round() / 1e6)
                ),
                &format!("at most {MAX_PLANT_DENSITY} plants per m2 of all types together"),
            ));
        }
        Ok(())
    }

    fn validate_derive(&self, v: &Validator, c: &DeriveCalibration) -> Result<(), WorldError> {
        let most = MAX_DERIVE_LOG2;
        v.within("derive.hurst", c.hurst, [-most, most], "")?;
        v.non_negative("derive.fit_rms_log2", c.fit_rms_log2)?;
        v.at_most("derive.fit_rms_log2", c.fit_rms_log2, most, "")?;
        v.non_negative("derive.residual_rms_m", c.residual_rms_m)?;
        let [lo, hi] = crate::world::PLAUSIBLE_HEIGHTS_M;
        v.at_most("derive.residual_rms_m", c.residual_rms_m, hi - lo, " m")?;
        v.non_negative("derive.decay_log2", c.decay_log2)?;
        v.at_most("derive.decay_log2", c.decay_log2, most, "")?;
        let levels = usize::from(self.pyramid.derived_levels);
        if c.detail.len() != levels {
            return Err(v.out_of_range(
                "derive.detail",
                format!("{} values", c.detail.len()),
                &format!("one value per derived level ({levels})"),
            ));
        }
        for (i, &d) in c.detail.iter().enumerate() {
            let field = format!("derive.detail[{i}]");
            v.non_negative(&field, d)?;
            if d > MAX_DETAIL {
                return Err(v.out_of_range(&field, d, &format!("at most {MAX_DETAIL}")));
            }
            if c.method == DeriveMode::Bicubic && d != 0.0 {
                return Err(v.out_of_range(&field, d, "0 when derive.method is \"bicubic\""));
            }
        }
        Ok(())
    }

    fn validate_path_wind(
        &self,
        v: &Validator,
        pi: usize,
        cam: &CameraPath,
    ) -> Result<(), WorldError> {
        if let Some(name) = &cam.walker
            && self.path(name).is_none()
        {
            return Err(WorldError::UnknownPathRef {
                path: v.path.to_path_buf(),
                field: format!("paths[{pi}].walker"),
                name: name.clone(),
            });
        }
        for (ki, key) in cam.wind.iter().enumerate() {
            let field = |f: &str| format!("paths[{pi}].wind[{ki}].{f}");
            v.time(&field("t_s"), key.t_s)?;
            v.non_negative(&field("blend_s"), key.blend_s)?;
            v.at_most(&field("blend_s"), key.blend_s, MAX_TIME_S, " s")?;
            if self.wind_scene(&key.scene).is_none() {
                return Err(WorldError::UnknownWindSceneRef {
                    path: v.path.to_path_buf(),
                    field: field("scene"),
                    name: key.scene.clone(),
                    available: crate::world::name_list(
                        self.wind_scenes.iter().map(|s| s.name.as_str()),
                    ),
                });
            }
            if ki > 0 {
                let prev = &cam.wind[ki - 1];
                if key.t_s < prev.t_s + prev.blend_s.max(1e-3) {
                    return Err(v.out_of_range(
                        &field("t_s"),
                        key.t_s,
                        &format!(
                            "at least {} (the previous wind key's t_s + blend_s): a scene \
                             change may not start before the one before it has blended in",
                            prev.t_s + prev.blend_s.max(1e-3)
                        ),
                    ));
                }
            }
        }
        Ok(())
    }

    fn validate_wind_scenes(&self, v: &Validator) -> Result<(), WorldError> {
        let mut names = HashSet::new();
        for (si, scene) in self.wind_scenes.iter().enumerate() {
            v.non_empty_name(&format!("wind_scenes[{si}].name"), &scene.name)?;
            if !names.insert(scene.name.as_str()) {
                return Err(WorldError::DuplicateWindScene {
                    path: v.path.to_path_buf(),
                    name: scene.name.clone(),
                });
            }
            v.validate_ambient(&format!("wind_scenes[{si}].ambient"), &scene.ambient)?;
            if scene.sources.len() > MAX_WIND_SOURCES {
                return Err(v.out_of_range(
                    &format!("wind_scenes[{si}].sources"),
                    format!("{} sources", scene.sources.len()),
                    &format!("at most {MAX_WIND_SOURCES} sources"),
                ));
            }
            for (ci, source) in scene.sources.iter().enumerate() {
                self.validate_wind_source(v, &format!("wind_scenes[{si}].sources[{ci}]"), source)?;
            }
        }
        Ok(())
    }

    fn validate_wind_source(
        &self,
        v: &Validator,
        at: &str,
        source: &WindSource,
    ) -> Result<(), WorldError> {
        let field = |f: &str| format!("{at}.{f}");
        match source {
            WindSource::Directional {
                direction_deg,
                speed_mps,
                ..
            } => {
                v.angle(&field("direction_deg"), *direction_deg)?;
                v.speed(&field("speed_mps"), *speed_mps)?;
            }
            WindSource::Omni {
                radius_m,
                speed_mps,
                ..
            } => {
                v.radius(&field("radius_m"), *radius_m)?;
                v.speed(&field("speed_mps"), *speed_mps)?;
            }
            WindSource::Vortex {
                radius_m,
                speed_mps,
                inflow_mps,
                ..
            } => {
                v.radius(&field("radius_m"), *radius_m)?;
                v.speed(&field("speed_mps"), *speed_mps)?;
                let most = MAX_WIND_SPEED_MPS;
                v.within(&field("inflow_mps"), *inflow_mps, [-most, most], " m/s")?;
            }
        }
        let (position, path_name, start_s, strength, _) = source.common();
        if let Some(p) = position {
            v.position(&field("position_m"), p)?;
        }
        match (position, path_name) {
            (Some(_), Some(_)) => {
                return Err(WorldError::WindSourcePlacement {
                    path: v.path.to_path_buf(),
                    field: at.to_string(),
                    message: "has both position_m and path: give one".into(),
                });
            }
            (None, None) if !matches!(source, WindSource::Directional { .. }) => {
                return Err(WorldError::WindSourcePlacement {
                    path: v.path.to_path_buf(),
                    field: at.to_string(),
                    message: format!(
                        "{} source needs position_m or path",
                        scenes::article(source.kind_name())
                    ),
                });
            }
            _ => {}
        }
        if let Some(name) = path_name
            && self.path(name).is_none()
        {
            return Err(WorldError::UnknownPathRef {
                path: v.path.to_path_buf(),
                field: field("path"),
                name: name.clone(),
            });
        }
        v.non_negative(&field("start_s"), start_s)?;
        v.at_most(&field("start_s"), start_s, MAX_TIME_S, " s")?;
        for (ki, key) in strength.iter().enumerate() {
            v.all_finite(&field(&format!("strength[{ki}]")), key)?;
            v.time(&field(&format!("strength[{ki}][0]")), key[0])?;
            let factor = field(&format!("strength[{ki}][1]"));
            v.non_negative(&factor, key[1])?;
            v.at_most(&factor, key[1], MAX_WIND_STRENGTH, "")?;
            if ki > 0 && key[0] <= strength[ki - 1][0] {
                return Err(WorldError::StrengthKeysOutOfOrder {
                    path: v.path.to_path_buf(),
                    field: field("strength"),
                    index: ki,
                    t_s: key[0],
                    previous_t_s: strength[ki - 1][0],
                });
            }
        }
        Ok(())
    }
}

/// A number of the manifest as its file writes it: a 32-bit field's value is the shortest decimal
/// that reads back as it (0.01, not 0.009999999776482582), so that a range's ends are inclusive
/// for what the file says and an error prints what the file holds.
trait Decimal: Copy {
    fn decimal(self) -> f64;
}

impl Decimal for f32 {
    fn decimal(self) -> f64 {
        // Rust prints an f32 as the shortest decimal that reads back as it.
        self.to_string().parse().unwrap_or(f64::from(self))
    }
}

impl Decimal for f64 {
    fn decimal(self) -> f64 {
        self
    }
}

impl Decimal for u32 {
    fn decimal(self) -> f64 {
        f64::from(self)
    }
}

/// Builds validation errors that name the manifest file.
struct Validator<'a> {
    path: &'a Path,
}

impl Validator<'_> {
    fn finite(&self, field: &str, value: impl Decimal) -> Result<(), WorldError> {
        let value = value.decimal();
        if value.is_finite() {
            Ok(())
        } else {
            Err(WorldError::NonFinite {
                path: self.path.to_path_buf(),
                field: field.to_string(),
                value,
            })
        }
    }

    fn all_finite<T: Decimal>(&self, field: &str, values: &[T]) -> Result<(), WorldError> {
        for (i, &x) in values.iter().enumerate() {
            self.finite(&format!("{field}[{i}]"), x)?;
        }
        Ok(())
    }

    fn positive(&self, field: &str, value: impl Decimal) -> Result<(), WorldError> {
        let value = value.decimal();
        self.finite(field, value)?;
        if value > 0.0 {
            Ok(())
        } else {
            Err(self.non_positive(field, value))
        }
    }

    fn non_negative(&self, field: &str, value: impl Decimal) -> Result<(), WorldError> {
        let value = value.decimal();
        self.finite(field, value)?;
        if value >= 0.0 {
            Ok(())
        } else {
            Err(WorldError::Negative {
                path: self.path.to_path_buf(),
                field: field.to_string(),
                value,
            })
        }
    }

    /// Refuses a finite `value` above `most` (`unit` follows the number in the message).
    fn at_most(
        &self,
        field: &str,
        value: impl Decimal,
        most: f64,
        unit: &str,
    ) -> Result<(), WorldError> {
        let value = value.decimal();
        self.finite(field, value)?;
        if value <= most {
            Ok(())
        } else {
            Err(self.out_of_range(
                field,
                number(value),
                &format!("at most {}{unit}", number(most)),
            ))
        }
    }

    /// Refuses a value that is not finite or lies outside `lo..=hi`.
    fn within(
        &self,
        field: &str,
        value: impl Decimal,
        [lo, hi]: [f64; 2],
        unit: &str,
    ) -> Result<(), WorldError> {
        let value = value.decimal();
        self.finite(field, value)?;
        if (lo..=hi).contains(&value) {
            Ok(())
        } else {
            let allowed = format!("in {}..={}{unit}", number(lo), number(hi));
            Err(self.out_of_range(field, number(value), &allowed))
        }
    }

    fn all_within<T: Decimal>(
        &self,
        field: &str,
        values: &[T],
        range: [f64; 2],
        unit: &str,
    ) -> Result<(), WorldError> {
        for (i, &x) in values.iter().enumerate() {
            self.within(&format!("{field}[{i}]"), x, range, unit)?;
        }
        Ok(())
    }

    fn angle(&self, field: &str, value: impl Decimal) -> Result<(), WorldError> {
        self.within(field, value, [-MAX_ANGLE_DEG, MAX_ANGLE_DEG], " degrees")
    }

    fn time(&self, field: &str, value: impl Decimal) -> Result<(), WorldError> {
        self.within(field, value, [-MAX_TIME_S, MAX_TIME_S], " s")
    }

    fn position(&self, field: &str, values: &[f64]) -> Result<(), WorldError> {
        self.all_within(field, values, [-MAX_POSITION_M, MAX_POSITION_M], " m")
    }

    fn speed(&self, field: &str, value: impl Decimal) -> Result<(), WorldError> {
        let value = value.decimal();
        self.non_negative(field, value)?;
        self.at_most(field, value, MAX_WIND_SPEED_MPS, " m/s")
    }

    fn radius(&self, field: &str, value: f64) -> Result<(), WorldError> {
        self.positive(field, value)?;
        self.at_most(field, value, MAX_WIND_RADIUS_M, " m")
    }

    /// An ambient wind (`[wind]` or a scene's `ambient`) at `at`.
    fn validate_ambient(&self, at: &str, a: &WindDefaults) -> Result<(), WorldError> {
        self.angle(&format!("{at}.direction_deg"), a.direction_deg)?;
        self.speed(&format!("{at}.speed_mps"), a.speed_mps)?;
        self.within(&format!("{at}.gustiness"), a.gustiness, [0.0, 1.0], "")
    }

    fn non_positive(&self, field: &str, value: f64) -> WorldError {
        WorldError::NonPositive {
            path: self.path.to_path_buf(),
            field: field.to_string(),
            value,
        }
    }

    /// Refuses a pyramid whose finest tiles (the grass's) are outside [`MIN_GRASS_TILE_M`] to
    /// [`MAX_GRASS_TILE_M`], naming `pyramid.derived_levels` and the values that would fit.
    fn grass_tiles(&self, p: &crate::world::Pyramid) -> Result<(), WorldError> {
        let finest = p.tile_size_m(p.max_level());
        if (MIN_GRASS_TILE_M..=MAX_GRASS_TILE_M).contains(&finest) {
            return Ok(());
        }
        // Derived levels halve the finest tile each: those that bring it within the range.
        let stored_finest = p.tile_size_m(p.stored_levels.saturating_sub(1));
        let most_derived = 24 - i32::from(p.stored_levels);
        let least = (stored_finest / MAX_GRASS_TILE_M).log2().ceil().max(0.0) as i32;
        let most = ((stored_finest / MIN_GRASS_TILE_M).log2().floor() as i32).min(most_derived);
        let fits = if least <= most {
            format!("{least}..={most} for this pyramid")
        } else {
            "none for this pyramid's root tiles and stored levels".to_owned()
        };
        Err(self.out_of_range(
            "pyramid.derived_levels",
            p.derived_levels,
            &format!(
                "a count that makes the finest tiles, where the grass grows, {MIN_GRASS_TILE_M} to \
                 {MAX_GRASS_TILE_M} m wide (they are {} m): {fits}, with one value a derived level \
                 in [derive] detail",
                number(finest)
            ),
        ))
    }

    /// Refuses a name that is empty or only blanks.
    fn non_empty_name(&self, field: &str, name: &str) -> Result<(), WorldError> {
        if name.trim().is_empty() {
            return Err(self.out_of_range(field, format!("{name:?}"), "a name, not empty"));
        }
        Ok(())
    }

    fn out_of_range(&self, field: &str, value: impl ToString, allowed: &str) -> WorldError {
        WorldError::OutOfRange {
            path: self.path.to_path_buf(),
            field: field.to_string(),
            value: value.to_string(),
            allowed: allowed.to_string(),
        }
    }
}

/// A number as messages show it: plainly, or in exponent form where plain digits would run
/// long (1e30 rather than thirty-one digits).
fn number(x: f64) -> String {
    let a = x.abs();
    if a != 0.0 && !(1e-4..1e9).contains(&a) {
        format!("{x:e}")
    } else {
        format!("{x}")
    }
}
