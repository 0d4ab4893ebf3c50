//! The document's check before anything is read from it.

use gltf::Gltf;

/// Checks the document as the gltf crate would, except for rules this loader does not rely on:
/// `POSITION`'s `min` and `max` (often left out by exporters), a primitive without `POSITION`
/// (skipped instead), and application-specific attribute names (ignored).
pub(super) fn validate(gltf: &Gltf) -> Result<(), String> {
    use gltf::json::validation::{Error, Validate};
    let root = gltf.as_json();
    // gltf-json's own check of POSITION looks its accessor up unchecked: check the index first.
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, primitive) in mesh.primitives.iter().enumerate() {
            for (semantic, index) in &primitive.attributes {
                if index.value() >= root.accessors.len() {
                    let name = match semantic {
                        gltf::json::validation::Checked::Valid(s) => s.to_string(),
                        gltf::json::validation::Checked::Invalid => "?".into(),
                    };
                    return Err(format!(
                        "meshes[{m}].primitives[{p}].attributes[\"{name}\"]: accessor {} does not exist",
                        index.value()
                    ));
                }
            }
        }
    }
    let mut errors = Vec::new();
    root.validate(root, gltf::json::Path::new, &mut |path, error| {
        let path = path().to_string();
        let tolerated = path.contains(".attributes[")
            && (path.ends_with("[\"POSITION\"].min")
                || path.ends_with("[\"POSITION\"].max")
                || (path.ends_with("[\"POSITION\"]") && error == Error::Missing)
                || (path.ends_with(']') && error == Error::Invalid));
        if !tolerated {
            errors.push(format!("{path}: {error}"));
        }
    });
    if errors.is_empty() {
        Ok(())
    } else {
        let more = if errors.len() > 3 {
            format!(" (and {} more)", errors.len() - 3)
        } else {
            String::new()
        };
        errors.truncate(3);
        Err(format!("{}{more}", errors.join("; ")))
    }
}
