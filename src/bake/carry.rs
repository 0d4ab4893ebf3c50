//! What a re-bake keeps of the manifest it replaces: the parts a bake never writes. A bake
//! derives the pyramid, the grass types, the wind, the sky and its own camera paths from the
//! DEM; the plant types and any camera path of another name were written by hand, and a
//! `bake --replace` that dropped them would lose the user's work. They are carried into the new
//! `world.toml` as their own text (comments kept), and the whole is checked as the world it
//! makes before anything is replaced.

use std::path::Path;

use crate::world::WorldError;
use crate::world::manifest::{CameraPath, Manifest, PlantType};

/// What was carried over from the replaced manifest.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Carried {
    /// Names of the plant types kept.
    pub plant_types: Vec<String>,
    /// Names of the camera paths kept (those the bake did not write itself).
    pub paths: Vec<String>,
}

impl Carried {
    /// Nothing was kept.
    pub fn is_empty(&self) -> bool {
        self.plant_types.is_empty() && self.paths.is_empty()
    }
}

/// A table header's kind, for the blocks carried.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Kind {
    Plant,
    Path,
}

/// One `[[plant_types]]` or `[[paths]]` element of the old text: its comment lines just above,
/// its header, its keys and its sub-tables (`[[paths.keys]]`, `[plant_types.wind]`, ...).
struct Block {
    kind: Kind,
    text: String,
}

/// `new_text` (the manifest a bake wrote) with the plant types of `old_text` and its camera
/// paths whose names the new one lacks. `old_path` names the replaced manifest in errors: a
/// manifest that does not parse, or a carried part that does not fit the new world (a plant
/// on a grass type it lacks, a path naming a wind scene it lacks), is refused before anything
/// is replaced.
pub(super) fn carry(
    new_text: &str,
    old_text: &str,
    old_path: &Path,
) -> Result<(String, Carried), WorldError> {
    let refuse = |e: WorldError| WorldError::Carry {
        path: old_path.to_path_buf(),
        source: Box::new(e),
    };
    let old = Manifest::parse(old_text, old_path).map_err(refuse)?;
    let new = Manifest::parse(new_text, old_path).map_err(refuse)?;
    let kept_paths: Vec<&CameraPath> = old
        .paths
        .iter()
        .filter(|p| new.path(&p.name).is_none())
        .collect();
    let carried = Carried {
        plant_types: old.plant_types.iter().map(|p| p.name.clone()).collect(),
        paths: kept_paths.iter().map(|p| p.name.clone()).collect(),
    };
    if carried.is_empty() {
        return Ok((new_text.to_owned(), carried));
    }
    let expected_plants: Vec<PlantType> = old.plant_types.clone();
    let mut expected_paths = new.paths.clone();
    expected_paths.extend(kept_paths.iter().map(|&p| p.clone()));

    // The old text's own blocks, where they can be told apart; else the parts as TOML.
    let from_text = blocks(old_text).and_then(|blocks| {
        let mut plant_i = 0;
        let mut path_i = 0;
        let mut extra = String::new();
        for b in &blocks {
            let keep = match b.kind {
                Kind::Plant => {
                    plant_i += 1;
                    true
                }
                Kind::Path => {
                    path_i += 1;
                    let name = &old.paths.get(path_i - 1)?.name;
                    new.path(name).is_none()
                }
            };
            if keep {
                extra.push('\n');
                extra.push_str(&b.text);
            }
        }
        (plant_i == old.plant_types.len() && path_i == old.paths.len()).then_some(extra)
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
        }
        let extra = Extra {
            plant_types: &old.plant_types,
            paths: kept_paths.clone(),
        };
        format!("\n{}", toml::to_string(&extra).unwrap_or_default())
    };
    let join = |extra: &str| format!("{}\n{extra}", new_text.trim_end());
    let fits = |text: &str| -> Result<bool, WorldError> {
        let m = Manifest::parse(text, old_path)?;
        Ok(m.plant_types == expected_plants && m.paths == expected_paths)
    };
    if let Some(extra) = from_text {
        let text = join(&extra);
        // A text the split misread (a header inside a multi-line string, say) gives other
        // parts than the manifest's own: then they are written from the parsed manifest.
        if fits(&text).unwrap_or(false) {
            return Ok((text, carried));
        }
    }
    let text = join(&from_serde());
    if fits(&text).map_err(refuse)? {
        Ok((text, carried))
    } else {
        Err(refuse(WorldError::ManifestSyntax {
            path: old_path.to_path_buf(),
            message: "its plant types and camera paths do not read back as written".into(),
        }))
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
