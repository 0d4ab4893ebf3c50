//! A plant written back as a glTF 2.0 file (the tests make their plant files with it).

use std::io;
use std::path::Path;

use base64::Engine as _;
use percent_encoding::{AsciiSet, NON_ALPHANUMERIC, utf8_percent_encode};
use serde_json::json;

use crate::plants::mesh::{PlantImage, PlantMesh};

/// Characters kept as they are in a written URI (RFC 3986's unreserved set).
const URI_KEEP: &AsciiSet = &NON_ALPHANUMERIC
    .remove(b'-')
    .remove(b'_')
    .remove(b'.')
    .remove(b'~');

/// Writes a plant as a `.gltf` file with one base64 data-URI buffer: positions, normals, uvs,
/// `COLOR_0` (the wind channels, RGBA float) and u32 indices, converted from plant space (z up)
/// back to glTF's y up. The material's `baseColorFactor` is the first vertex's albedo. When
/// `base_color` is given it is written as a PNG beside the file (`<stem>_base_color.png`) and
/// named as the material's base colour texture.
///
/// An empty mesh, an index past the vertices, or an image whose bytes do not match its size is
/// refused with [`io::ErrorKind::InvalidInput`].
pub fn write_plant_gltf(
    path: &Path,
    mesh: &PlantMesh,
    base_color: Option<&PlantImage>,
) -> io::Result<()> {
    let invalid = |m: String| io::Error::new(io::ErrorKind::InvalidInput, m);
    if mesh.vertices.is_empty() || mesh.indices.is_empty() {
        return Err(invalid("a plant mesh needs vertices and triangles".into()));
    }
    let n = mesh.vertices.len();
    if let Some(&i) = mesh.indices.iter().find(|&&i| i as usize >= n) {
        return Err(invalid(format!(
            "index {i} is out of range for {n} vertices"
        )));
    }
    // Plant (x, y, z) z-up -> glTF (x, z, -y) y-up.
    let to_gltf = |v: [f32; 3]| [v[0], v[2], -v[1]];
    let mut bin: Vec<u8> = Vec::new();
    let mut views = Vec::new();
    let mut push_view = |bin: &mut Vec<u8>, data: &[u8], target: u32| {
        let offset = bin.len();
        bin.extend_from_slice(data);
        views.push(
            json!({"buffer": 0, "byteOffset": offset, "byteLength": data.len(), "target": target}),
        );
        views.len() - 1
    };
    const ARRAY_BUFFER: u32 = 34962;
    const ELEMENT_ARRAY_BUFFER: u32 = 34963;
    let positions: Vec<[f32; 3]> = mesh.vertices.iter().map(|v| to_gltf(v.position)).collect();
    let normals: Vec<[f32; 3]> = mesh.vertices.iter().map(|v| to_gltf(v.normal)).collect();
    let uvs: Vec<[f32; 2]> = mesh.vertices.iter().map(|v| v.uv).collect();
    let colors: Vec<[f32; 4]> = mesh.vertices.iter().map(|v| v.wind).collect();
    let mut min = [f32::INFINITY; 3];
    let mut max = [f32::NEG_INFINITY; 3];
    for p in &positions {
        for k in 0..3 {
            min[k] = min[k].min(p[k]);
            max[k] = max[k].max(p[k]);
        }
    }
    let v_pos = push_view(&mut bin, bytemuck::cast_slice(&positions), ARRAY_BUFFER);
    let v_nrm = push_view(&mut bin, bytemuck::cast_slice(&normals), ARRAY_BUFFER);
    let v_uv = push_view(&mut bin, bytemuck::cast_slice(&uvs), ARRAY_BUFFER);
    let v_col = push_view(&mut bin, bytemuck::cast_slice(&colors), ARRAY_BUFFER);
    let v_idx = push_view(
        &mut bin,
        bytemuck::cast_slice(&mesh.indices),
        ELEMENT_ARRAY_BUFFER,
    );
    const FLOAT: u32 = 5126;
    const UNSIGNED_INT: u32 = 5125;
    let albedo = mesh.vertices[0].albedo;
    let mut material = json!({
        "pbrMetallicRoughness": {
            "baseColorFactor": [albedo[0], albedo[1], albedo[2], 1.0],
            "metallicFactor": 0.0,
        },
        "doubleSided": true,
    });
    let mut doc = json!({
        "asset": {"version": "2.0", "generator": "verdant"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{
            "attributes": {"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2, "COLOR_0": 3},
            "indices": 4,
            "material": 0,
            "mode": 4,
        }]}],
        "accessors": [
            {"bufferView": v_pos, "componentType": FLOAT, "count": n, "type": "VEC3", "min": min, "max": max},
            {"bufferView": v_nrm, "componentType": FLOAT, "count": n, "type": "VEC3"},
            {"bufferView": v_uv, "componentType": FLOAT, "count": n, "type": "VEC2"},
            {"bufferView": v_col, "componentType": FLOAT, "count": n, "type": "VEC4"},
            {"bufferView": v_idx, "componentType": UNSIGNED_INT, "count": mesh.indices.len(), "type": "SCALAR"},
        ],
        "bufferViews": views,
        "buffers": [{
            "byteLength": bin.len(),
            "uri": format!(
                "data:application/octet-stream;base64,{}",
                base64::engine::general_purpose::STANDARD.encode(&bin)
            ),
        }],
    });
    if let Some(img) = base_color {
        let rgba = image::RgbaImage::from_raw(img.width, img.height, img.rgba.clone()).ok_or_else(
            || {
                invalid(format!(
                    "the base colour image has {} bytes, not {}x{}x4",
                    img.rgba.len(),
                    img.width,
                    img.height
                ))
            },
        )?;
        let stem = path
            .file_stem()
            .map_or_else(|| "plant".into(), |s| s.to_string_lossy().into_owned());
        let name = format!("{stem}_base_color.png");
        let png_path = path.with_file_name(&name);
        rgba.save_with_format(&png_path, image::ImageFormat::Png)
            .map_err(io::Error::other)?;
        material["pbrMetallicRoughness"]["baseColorTexture"] = json!({"index": 0});
        doc["textures"] = json!([{"source": 0}]);
        doc["images"] = json!([{"uri": utf8_percent_encode(&name, URI_KEEP).to_string()}]);
    }
    doc["materials"] = json!([material]);
    let text = serde_json::to_string_pretty(&doc).map_err(io::Error::other)?;
    std::fs::write(path, text)
}
