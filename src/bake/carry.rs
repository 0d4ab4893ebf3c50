//! What a re-bake keeps of the manifest it replaces: the parts a bake never writes. A bake
//! derives the pyramid, the grass types, the wind, the sky and its own camera paths and wind
//! scenes from the DEM; the plant types and any camera path or wind scene of another name were
//! written by hand, and a `bake --replace` that dropped them would lose the user's work. They
//! are carried into the new `world.toml` as their own text (comments kept), and the whole is
//! checked as the world it makes before anything is replaced.

use std::path::Path;

use crate::world::WorldError;
use crate::world::manifest::{CameraPath, Manifest, PlantType, WindScene};

/// What was carried over from the replaced manifest.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Carried {
    /// Names of the plant types kept.
    pub plant_types: Vec<String>,
    /// Names of the camera paths kept (those the bake did not write itself).
    pub paths: Vec<String>,
    /// Names of the wind scenes kept (those the bake did not write itself).
    #[serde(default)]
    pub wind_scenes: Vec<String>,
    /// Kept paths with a key outside the new world's data area.
    #[serde(default)]
    pub paths_outside: Vec<String>,
    /// The replaced manifest's paths and wind scenes of the bake's own names that differ from
    /// what the bake wrote (hand-edited ones, or fitted to other terrain): the bake's replace
    /// them.
    #[serde(default)]
    pub replaced: Vec<String>,
    /// The kept parts could not be told apart in the old text (an inline array, a header
    /// inside a multi-line string): they were written from the parsed manifest, with every
    /// field spelt out and without their comments.
    #[serde(default)]
    pub rewritten: bool,
}

impl Carried {
    /// Nothing was kept.
    pub fn is_empty(&self) -> bool {
        self.plant_types.is_empty() && self.paths.is_empty() && self.wind_scenes.is_empty()
    }
}

/// A kept table's kind.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Kind {
    Plant,
    Path,
    Scene,
}

/// One `[[plant_types]]`, `[[paths]]` or `[[wind_scenes]]` element of the old text: its
/// comment lines just above, its header, its keys and its sub-tables (`[[paths.keys]]`,
/// `[plant_types.wind]`, ...).
struct Block {
    kind: Kind,
    text: String,
}

/// The parts of an old manifest that a bake keeps. Only they are read (the rest is the bake's
/// again), so that an old manifest that a newer loader refuses elsewhere (its pyramid, a
/// colour) can still be re-baked with its hand-made parts; they are checked as parts of the new
/// manifest.
#[derive(serde::Deserialize)]
pub(super) struct KeptParts {
    #[serde(default)]
    plant_types: Vec<PlantType>,
    #[serde(default)]
    paths: Vec<CameraPath>,
    #[serde(default)]
    wind_scenes: Vec<WindScene>,
}

pub(super) fn kept_parts(old_text: &str, old_path: &Path) -> Result<KeptParts, WorldError> {
    let syntax = |message: String| WorldError::ManifestSyntax {
        path: old_path.to_path_buf(),
        message: message.trim_end().to_owned(),
    };
    // Read from the text itself (the other keys ignored), so that an error names its line.
    toml::from_str(old_text).map_err(|e| syntax(crate::world::manifest::toml_error(old_text, &e)))
}

/// `new_text` (the manifest a bake wrote) with the plant types of `old_text`, and its camera
/// paths and wind scenes whose names the new one lacks. `old_path` names the replaced manifest
/// in errors: a manifest that does not parse, or a carried part that does not fit the new world
/// (a plant on a grass type it lacks, a path naming a wind scene nobody has), is refused before
/// anything is replaced, saying where the kept parts stand in the new manifest.
pub(super) fn carry(
    new_text: &str,
    old_text: &str,
    old_path: &Path,
) -> Result<(String, Carried), WorldError> {
    let refuse = |e: WorldError, kept: String| WorldError::Carry {
        path: old_path.to_path_buf(),
        kept,
        source: Box::new(e),
    };
    let old = kept_parts(old_text, old_path).map_err(|e| refuse(e, String::new()))?;
    let new = Manifest::parse(new_text, old_path).map_err(|e| refuse(e, String::new()))?;
    let kept_paths: Vec<&CameraPath> = old
        .paths
        .iter()
        .filter(|p| new.path(&p.name).is_none())
        .collect();
    let kept_scenes: Vec<&WindScene> = old
        .wind_scenes
        .iter()
        .filter(|s| new.wind_scene(&s.name).is_none())
        .collect();
    let [ex, ey] = new.extent_m;
    let mut carried = Carried {
        plant_types: old.plant_types.iter().map(|p| p.name.clone()).collect(),
        paths: kept_paths.iter().map(|p| p.name.clone()).collect(),
        wind_scenes: kept_scenes.iter().map(|s| s.name.clone()).collect(),
        paths_outside: kept_paths
            .iter()
            .filter(|p| {
                p.keys.iter().any(|k| {
                    let [x, y, _] = k.position_m;
                    !((0.0..=ex).contains(&x) && (0.0..=ey).contains(&y))
                })
            })
            .map(|p| p.name.clone())
            .collect(),
        replaced: old
            .paths
            .iter()
            .filter(|p| new.path(&p.name).is_some_and(|n| n != *p))
            .map(|p| format!("path {:?}", p.name))
            .chain(
                old.wind_scenes
                    .iter()
                    .filter(|s| new.wind_scene(&s.name).is_some_and(|n| n != *s))
                    .map(|s| format!("wind scene {:?}", s.name)),
            )
            .collect(),
        rewritten: false,
    };
    if carried.is_empty() {
        return Ok((new_text.to_owned(), carried));
    }
    // Where the kept parts stand in the new manifest, for errors that name them by index.
    let mut at = Vec::new();
    if !old.plant_types.is_empty() {
        at.push(format!(
            "plant_types[0..{}] are its plant types",
            old.plant_types.len()
        ));
    }
    for (i, p) in kept_paths.iter().enumerate() {
        at.push(format!(
            "paths[{}] is its path {:?}",
            new.paths.len() + i,
            p.name
        ));
    }
    for (i, s) in kept_scenes.iter().enumerate() {
        at.push(format!(
            "wind_scenes[{}] is its wind scene {:?}",
            new.wind_scenes.len() + i,
            s.name
        ));
    }
    let kept = at.join(", ");
    let expected_plants: Vec<PlantType> = old.plant_types.clone();
    let mut expected_paths = new.paths.clone();
    expected_paths.extend(kept_paths.iter().map(|&p| p.clone()));
    let mut expected_scenes = new.wind_scenes.clone();
    expected_scenes.extend(kept_scenes.iter().map(|&s| s.clone()));

    // The old text's own blocks, where they can be told apart; else the parts as TOML.
    let from_text = blocks(old_text).and_then(|blocks| {
        let (mut plant_i, mut path_i, mut scene_i) = (0, 0, 0);
        let mut extra = String::new();
        for b in &blocks {
            let keep = match b.kind {
                Kind::Plant => {
                    plant_i += 1;
                    true
                }
                Kind::Path => {
                    path_i += 1;
                    new.path(&old.paths.get(path_i - 1)?.name).is_none()
                }
                Kind::Scene => {
                    scene_i += 1;
                    new.wind_scene(&old.wind_scenes.get(scene_i - 1)?.name)
                        .is_none()
                }
            };
            if keep {
                extra.push('\n');
                extra.push_str(&b.text);
            }
        }
        (plant_i == old.plant_types.len()
            && path_i == old.paths.len()
            && scene_i == old.wind_scenes.len())
        .then_some(extra)
    });
    let from_serde = || {
        #[derive(serde::Serialize)]
        struct Extra<'a> {
            // An empty list would be written as a plain key (`paths = []`), which after the
            // new manifest's last table would land inside it.
            #[serde(skip_serializing_if = "<[_]>::is_empty")]
            plant_types: &'a [PlantType],
            #[serde(skip_serializing_if = "Vec::is_empty")]
            paths: Vec<&'a CameraPath>,
            #[serde(skip_serializing_if = "Vec::is_empty")]
            wind_scenes: Vec<&'a WindScene>,
        }
        let extra = Extra {
            plant_types: &old.plant_types,
            paths: kept_paths.clone(),
            wind_scenes: kept_scenes.clone(),
        };
        format!("\n{}", toml::to_string(&extra).unwrap_or_default())
    };
    let join = |extra: &str| format!("{}\n{extra}", new_text.trim_end());
    let fits = |text: &str| -> Result<bool, WorldError> {
        let m = Manifest::parse(text, old_path)?;
        Ok(m.plant_types == expected_plants
            && m.paths == expected_paths
            && m.wind_scenes == expected_scenes)
    };
    if let Some(extra) = from_text {
        let text = join(&extra);
        // A text the split misread (a header inside a multi-line string, say) gives other
        // parts than the manifest's own: then they are written from the parsed manifest.
        if fits(&text).unwrap_or(false) {
            return Ok((text, carried));
        }
    }
    carried.rewritten = true;
    let text = join(&from_serde());
    if fits(&text).map_err(|e| refuse(e, kept.clone()))? {
        Ok((text, carried))
    } else {
        Err(refuse(
            WorldError::ManifestSyntax {
                path: old_path.to_path_buf(),
                message: "its plant types, camera paths and wind scenes do not read back as \
                          written"
                    .into(),
            },
            kept,
        ))
    }
}

/// The key of a table header line (`[a.b]` or `[[a.b]]`, a comment after it allowed), its
/// dotted parts unquoted, and whether it is an array's; `None` for any other line.
fn header(line: &str) -> Option<(Vec<String>, bool)> {
    let t = line.trim();
    let array = t.starts_with("[[");
    let inner = if array {
        t.strip_prefix("[[")?.split("]]").next()?
    } else {
        t.strip_prefix('[')?.split(']').next()?
    };
    let parts: Vec<String> = inner
        .split('.')
        .map(|p| p.trim().trim_matches(['"', '\'']).to_owned())
        .collect();
    (!parts.iter().any(String::is_empty)).then_some((parts, array))
}

/// The `[[plant_types]]` and `[[paths]]` elements of `text` in order, each with the comment
/// lines right above its header and its sub-tables; `None` where a header of them is not an
/// array's (`[plant_types]`), which the split cannot follow.
fn blocks(text: &str) -> Option<Vec<Block>> {
    let lines: Vec<&str> = text.lines().collect();
    // Each header's line, and where its chunk starts: the comment lines right above it.
    let mut starts = Vec::new();
    for (i, line) in lines.iter().enumerate() {
        if let Some((key, array)) = header(line) {
            let floor = starts
                .last()
                .map_or(0, |&(h, _, _, _): &(usize, usize, _, _)| h + 1);
            let mut s = i;
            while s > floor && lines[s - 1].trim_start().starts_with('#') {
                s -= 1;
            }
            starts.push((i, s, key, array));
        }
    }
    let mut out: Vec<Block> = Vec::new();
    // The block being gathered: its kind and whether the chunks now read belong to it.
    let mut open: Option<Kind> = None;
    for (n, (_, start, key, array)) in starts.iter().enumerate() {
        let end = starts.get(n + 1).map_or(lines.len(), |&(_, s, _, _)| s);
        let chunk = lines[*start..end].join("\n");
        let kind = match key[0].as_str() {
            "plant_types" => Some(Kind::Plant),
            "paths" => Some(Kind::Path),
            "wind_scenes" => Some(Kind::Scene),
            _ => None,
        };
        match kind {
            Some(k) if key.len() == 1 => {
                if !array {
                    return None;
                }
                out.push(Block {
                    kind: k,
                    text: format!("{}\n", chunk.trim_end()),
                });
                open = Some(k);
            }
            Some(k) if open == Some(k) => {
                let b = out.last_mut()?;
                b.text.push_str(chunk.trim_end());
                b.text.push('\n');
            }
            // A sub-table before any element of its array: not a manifest's.
            Some(_) => return None,
            None => open = None,
        }
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A manifest of `grass` types (bare first) and one path, `extra` appended.
    fn manifest(grass: &[&str], extra: &str) -> String {
        let mut t = String::from(
            "name = \"t\"\nextent_m = [900.0, 1000.0]\nheight_range_m = [0.0, 500.0]\n\
             [pyramid]\nroot_tile_size_m = 512.0\nroot_tiles = [2, 2]\ntile_cells = 16\n\
             border = 2\nstored_levels = 2\nderived_levels = 1\n",
        );
        for g in grass {
            t.push_str(&format!(
                "[[grass_types]]\nname = \"{g}\"\nground_color = [0.3, 0.3, 0.3]\n\
                 base_color = [0.3, 0.3, 0.3]\ntip_color = [0.3, 0.3, 0.3]\n\
                 height_m = [0.2, 0.4]\nwidth_m = [0.01, 0.02]\nstiffness = 0.5\n"
            ));
        }
        t.push_str(
            "[[paths]]\nname = \"tour\"\nduration_s = 10.0\nkeys = [\n\
             { t_s = 0.0, position_m = [10.0, 10.0, 600.0], yaw_deg = 45.0, pitch_deg = -10.0 },\n\
             { t_s = 10.0, position_m = [800.0, 900.0, 600.0], yaw_deg = 45.0, pitch_deg = -10.0 },\n]\n",
        );
        t.push_str(extra);
        t
    }

    #[test]
    fn a_kept_part_that_does_not_fit_the_new_world_is_refused_saying_where_it_stands() {
        let plant = "# moss lovers\n[[plant_types]]\nname = \"fern\"\nmesh = \"fern\"\n\
                     color = [0.1, 0.3, 0.05]\nsize_m = [0.5, 0.9]\ndensity = { moss = 0.2 }\n";
        let old = manifest(&["bare", "meadow", "moss"], plant);
        let new = manifest(&["bare", "meadow"], "");
        let path = Path::new("w/world.toml");
        let e = carry(&new, &old, path).unwrap_err().to_string();
        for needle in [
            "plant_types[0].density.moss",
            "plant_types[0..1] are its plant types",
            "w/world.toml",
            "--fresh-manifest",
        ] {
            assert!(e.contains(needle), "{needle:?} not in {e:?}");
        }
        // With the grass type, it is kept with its comment.
        let new = manifest(&["bare", "meadow", "moss"], "");
        let (text, carried) = carry(&new, &old, path).unwrap();
        assert_eq!(carried.plant_types, ["fern"]);
        assert!(text.contains("# moss lovers") && !carried.rewritten);
    }

    /// A kept part the old manifest gets wrong is refused at the line it is on, like any
    /// other error of a manifest.
    #[test]
    fn a_kept_part_missing_a_field_is_refused_at_its_line() {
        let old = manifest(&["bare", "meadow"], "[[plant_types]]\n");
        let line = old.lines().position(|l| l == "[[plant_types]]").unwrap() + 1;
        let e = kept_parts(&old, Path::new("w/world.toml"))
            .err()
            .expect("a plant type without a name")
            .to_string();
        for needle in [
            "w/world.toml".to_string(),
            "missing field `name`".to_string(),
            format!("line {line}"),
        ] {
            assert!(e.contains(&needle), "{needle:?} not in {e:?}");
        }
    }

    #[test]
    fn headers_are_read_with_quotes_and_comments_and_other_lines_are_not() {
        assert_eq!(
            header("[[plant_types]]"),
            Some((vec!["plant_types".into()], true))
        );
        assert_eq!(
            header("  [[ paths . \"keys\" ]]  # the keys"),
            Some((vec!["paths".into(), "keys".into()], true))
        );
        assert_eq!(header("[sky]"), Some((vec!["sky".into()], false)));
        assert_eq!(header("name = \"[x]\""), None);
        assert_eq!(header("# [[plant_types]]"), None);
        assert_eq!(header("[]"), None);
    }

    #[test]
    fn blocks_take_their_comments_and_sub_tables_and_stop_at_other_tables() {
        let text = "name = \"w\"\n\n# flowers\n# two lines\n[[plant_types]]\nname = \"a\"\n\
                    [plant_types.wind]\nbend = 0.1\n\n[[paths]]\nname = \"p\"\n[[paths.keys]]\n\
                    t_s = 0.0\n# about the sky\n[sky]\nsun = 1\n[[plant_types]]\nname = \"b\"\n";
        let b = blocks(text).unwrap();
        assert_eq!(b.len(), 3);
        assert_eq!(b[0].kind, Kind::Plant);
        assert_eq!(
            b[0].text,
            "# flowers\n# two lines\n[[plant_types]]\nname = \"a\"\n[plant_types.wind]\nbend = 0.1\n"
        );
        assert_eq!(b[1].kind, Kind::Path);
        assert_eq!(
            b[1].text,
            "[[paths]]\nname = \"p\"\n[[paths.keys]]\nt_s = 0.0\n"
        );
        assert_eq!(b[2].text, "[[plant_types]]\nname = \"b\"\n");
        // A plain table of either name cannot be split.
        assert!(blocks("[plant_types]\nname = \"a\"\n").is_none());
    }
}
