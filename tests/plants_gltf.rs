//! The glTF plant loader: round trips through the writer, hand-made .glb files, every error it
//! names, and garbled files that must give errors rather than panics.

mod common;

use std::path::{Path, PathBuf};

use serde_json::{Value, json};
use verdant::plants::{
    MAX_PLANT_BUFFER_BYTES, MAX_PLANT_TRIANGLES, MAX_PLANT_VERTICES, MAX_TEXTURE_SIZE,
    PlantFileError, PlantImage, PlantMesh, PlantTexture, PlantVertex, load_plant, write_plant_gltf,
};

/// A glTF binary: header, JSON chunk (space padded), BIN chunk (zero padded) when not empty.
fn glb(json: &Value, bin: &[u8]) -> Vec<u8> {
    let mut j = serde_json::to_vec(json).unwrap();
    while !j.len().is_multiple_of(4) {
        j.push(b' ');
    }
    let mut b = bin.to_vec();
    while !b.len().is_multiple_of(4) {
        b.push(0);
    }
    let total = 12 + 8 + j.len() + if b.is_empty() { 0 } else { 8 + b.len() };
    let mut out = Vec::new();
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(j.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&j);
    if !b.is_empty() {
        out.extend_from_slice(&(b.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&b);
    }
    out
}

/// One y-up triangle (0,0,0) (1,0,0) (0,1,0) on a node moved by (1, 2, 3), with COLOR_0 as
/// normalised RGB bytes (stride 4) and u16 indices; POSITION has no min or max.
fn triangle() -> (Value, Vec<u8>) {
    let mut bin = Vec::new();
    for p in [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]] {
        for c in p {
            bin.extend_from_slice(&c.to_le_bytes());
        }
    }
    for c in [[255u8, 0, 128], [0, 255, 0], [51, 102, 204]] {
        bin.extend_from_slice(&c);
        bin.push(0);
    }
    for i in [0u16, 1, 2] {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    bin.extend_from_slice(&[0, 0]);
    let doc = json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "translation": [1.0, 2.0, 3.0]}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "COLOR_0": 1}, "indices": 2}]}],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"},
            {"bufferView": 1, "componentType": 5121, "normalized": true, "count": 3, "type": "VEC3"},
            {"bufferView": 2, "componentType": 5123, "count": 3, "type": "SCALAR"},
        ],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 36},
            {"buffer": 0, "byteOffset": 36, "byteLength": 12, "byteStride": 4},
            {"buffer": 0, "byteOffset": 48, "byteLength": 6},
        ],
        "buffers": [{"byteLength": 56}],
    });
    (doc, bin)
}

/// `triangle()` with a PNG in the BIN chunk named as base colour and thickness texture.
fn triangle_with_texture(png: &[u8]) -> (Value, Vec<u8>) {
    let (mut doc, mut bin) = triangle();
    let offset = bin.len();
    bin.extend_from_slice(png);
    doc["bufferViews"]
        .as_array_mut()
        .unwrap()
        .push(json!({"buffer": 0, "byteOffset": offset, "byteLength": png.len()}));
    doc["buffers"][0]["byteLength"] = json!(bin.len());
    doc["images"] = json!([{"bufferView": 3, "mimeType": "image/png"}]);
    doc["textures"] = json!([{"source": 0}]);
    doc["materials"] = json!([{
        "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}, "baseColorFactor": [0.25, 0.5, 0.75, 1.0]},
        "extensions": {"KHR_materials_volume": {"thicknessTexture": {"index": 0}}},
    }]);
    doc["extensionsUsed"] = json!(["KHR_materials_volume"]);
    doc["meshes"][0]["primitives"][0]["material"] = json!(0);
    (doc, bin)
}

fn image(width: u32, height: u32) -> PlantImage {
    let rgba = (0..width * height * 4)
        .map(|i| (i * 37 % 251) as u8)
        .collect();
    PlantImage {
        width,
        height,
        rgba,
    }
}

fn png(img: &PlantImage) -> Vec<u8> {
    let mut out = std::io::Cursor::new(Vec::new());
    image::RgbaImage::from_raw(img.width, img.height, img.rgba.clone())
        .unwrap()
        .write_to(&mut out, image::ImageFormat::Png)
        .unwrap();
    out.into_inner()
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

/// The error, after checking that its message names the file.
fn load_err(path: &Path) -> PlantFileError {
    let err = load_plant(path).expect_err("the file must be refused");
    let message = err.to_string();
    assert!(
        message.contains(&path.display().to_string()),
        "{message:?} does not name {}",
        path.display()
    );
    err
}

/// Two triangles of a small upright leaf in plant space (z up), each vertex painted apart.
fn leaf() -> PlantMesh {
    let corners = [
        [0.0, 0.0, 0.0],
        [0.2, 0.1, 0.3],
        [-0.1, -0.3, 0.6],
        [0.05, 0.4, 0.9],
    ];
    let vertices = corners
        .iter()
        .enumerate()
        .map(|(i, &position)| {
            let f = i as f32;
            PlantVertex {
                position,
                normal: [0.0, -0.6, 0.8],
                wind: [0.1 * f, 0.2 + 0.1 * f, 0.25 * f, 1.0 - 0.2 * f],
                albedo: [0.2, 0.6, 0.1, 0.5],
                uv: [0.25 * f, 1.0 - 0.25 * f],
            }
        })
        .collect();
    PlantMesh {
        vertices,
        indices: vec![0, 1, 2, 2, 1, 3],
    }
}

fn close(a: [f32; 3], b: [f32; 3], eps: f32) -> bool {
    a.iter().zip(b).all(|(x, y)| (x - y).abs() <= eps)
}

#[test]
fn round_trip_keeps_positions_normals_uvs_and_colour_channels() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("leaf.gltf");
    let mesh = leaf();
    write_plant_gltf(&path, &mesh, None).unwrap();

    // The file is y-up: the leaf's top (plant z 0.9) is glTF y 0.9, plant y 0.4 is glTF z -0.4.
    let doc: Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    let max = &doc["accessors"][0]["max"];
    assert_eq!(max[1].as_f64().unwrap() as f32, 0.9);
    assert_eq!(doc["accessors"][0]["min"][2].as_f64().unwrap() as f32, -0.4);

    let plant = load_plant(&path).unwrap();
    assert_eq!(plant.mesh.indices, mesh.indices);
    assert_eq!(plant.mesh.vertices.len(), mesh.vertices.len());
    for (got, want) in plant.mesh.vertices.iter().zip(&mesh.vertices) {
        assert!(
            close(got.position, want.position, 1e-6),
            "{got:?} vs {want:?}"
        );
        assert!(close(got.normal, want.normal, 1e-6), "{got:?} vs {want:?}");
        assert_eq!(got.uv, want.uv);
        assert_eq!(got.wind, want.wind);
        assert_eq!(got.albedo, [0.2, 0.6, 0.1, 0.5]);
    }
    assert_eq!(plant.base_color, None);
    assert_eq!(plant.thickness, None);
}

#[test]
fn glb_by_hand_applies_node_transform_axes_and_byte_colours() {
    let dir = tempfile::tempdir().unwrap();
    let (doc, bin) = triangle();
    let path = write(dir.path(), "tri.glb", &glb(&doc, &bin));
    let plant = load_plant(&path).unwrap();
    let positions: Vec<[f32; 3]> = plant.mesh.vertices.iter().map(|v| v.position).collect();
    // glTF (x, y, z) + (1, 2, 3) then (x, -z, y).
    assert_eq!(
        positions,
        vec![[1.0, -3.0, 2.0], [2.0, -3.0, 2.0], [1.0, -3.0, 3.0]]
    );
    assert_eq!(plant.mesh.indices, vec![0, 1, 2]);
    for v in &plant.mesh.vertices {
        // Computed: the triangle faces glTF +z, plant -y.
        assert!(close(v.normal, [0.0, -1.0, 0.0], 1e-6), "{:?}", v.normal);
        assert_eq!(v.uv, [0.0, 0.0]);
        // No material: glTF's default white.
        assert_eq!(v.albedo, [1.0, 1.0, 1.0, 0.5]);
    }
    let wind: Vec<[f32; 4]> = plant.mesh.vertices.iter().map(|v| v.wind).collect();
    assert_eq!(
        wind,
        vec![
            [1.0, 0.0, 128.0 / 255.0, 1.0],
            [0.0, 1.0, 0.0, 1.0],
            [0.2, 0.4, 0.8, 1.0]
        ]
    );
}

#[test]
fn without_colours_freedom_grows_with_height() {
    let dir = tempfile::tempdir().unwrap();
    let (mut doc, bin) = triangle();
    doc["meshes"][0]["primitives"][0]["attributes"] = json!({"POSITION": 0});
    let path = write(dir.path(), "plain.glb", &glb(&doc, &bin));
    let plant = load_plant(&path).unwrap();
    let wind: Vec<[f32; 4]> = plant.mesh.vertices.iter().map(|v| v.wind).collect();
    assert_eq!(
        wind,
        vec![
            [0.0, 0.0, 2.0 / 3.0, 1.0],
            [0.0, 0.0, 2.0 / 3.0, 1.0],
            [0.0, 0.0, 1.0, 1.0]
        ]
    );
}

#[test]
fn lines_are_skipped_and_a_mirroring_node_keeps_faces_front() {
    let dir = tempfile::tempdir().unwrap();
    let (mut doc, bin) = triangle();
    let tri = doc["meshes"][0]["primitives"][0].clone();
    let mut lines = tri.clone();
    lines["mode"] = json!(1);
    doc["meshes"][0]["primitives"] = json!([lines, tri]);
    doc["nodes"][0]["scale"] = json!([-1.0, 1.0, 1.0]);
    let path = write(dir.path(), "mirror.glb", &glb(&doc, &bin));
    let plant = load_plant(&path).unwrap();
    assert_eq!(plant.mesh.vertices.len(), 3);
    // Mirrored in x, the winding is turned back so that the front still faces plant -y.
    assert_eq!(plant.mesh.indices, vec![0, 2, 1]);
    assert!(close(plant.mesh.vertices[0].normal, [0.0, -1.0, 0.0], 1e-6));

    // Lines alone leave nothing to draw.
    doc["meshes"][0]["primitives"] = json!([lines]);
    let path = write(dir.path(), "lines.glb", &glb(&doc, &bin));
    assert!(matches!(load_err(&path), PlantFileError::NoMesh { .. }));
}

#[test]
fn texture_round_trip_through_a_png_beside_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("fern leaf.gltf");
    let img = image(3, 2);
    write_plant_gltf(&path, &leaf(), Some(&img)).unwrap();
    assert!(dir.path().join("fern leaf_base_color.png").exists());
    let plant = load_plant(&path).unwrap();
    assert_eq!(plant.base_color, Some(img));
    assert_eq!(plant.thickness, None);
}

#[test]
fn glb_textures_from_a_buffer_view_give_base_colour_and_thickness() {
    let dir = tempfile::tempdir().unwrap();
    let img = image(4, 5);
    let (doc, bin) = triangle_with_texture(&png(&img));
    let path = write(dir.path(), "textured.glb", &glb(&doc, &bin));
    let plant = load_plant(&path).unwrap();
    assert_eq!(plant.base_color.as_ref(), Some(&img));
    assert_eq!(plant.thickness.as_ref(), Some(&img));
    assert_eq!(plant.mesh.vertices[0].albedo, [0.25, 0.5, 0.75, 0.5]);
}

#[test]
fn missing_file_is_a_read_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("absent.gltf");
    match load_err(&path) {
        PlantFileError::Read { source, .. } => {
            assert_eq!(source.kind(), std::io::ErrorKind::NotFound)
        }
        other => panic!("{other:?}"),
    }
}

/// A plant file, or a buffer it names, that is a device, a FIFO or larger than a plant's file
/// may be is refused by name without being read: no hang, no memory run out.
#[cfg(unix)]
#[test]
fn special_and_oversized_plant_files_are_refused_without_reading_them() {
    use verdant::plants::gltf::MAX_PLANT_FILE_BYTES;
    let dir = tempfile::tempdir().unwrap();
    let zero = dir.path().join("zero.glb");
    std::os::unix::fs::symlink("/dev/zero", &zero).unwrap();
    let fifo = dir.path().join("fifo.glb");
    common::mkfifo(&fifo);
    let huge = dir.path().join("huge.glb");
    std::fs::File::create(&huge)
        .unwrap()
        .set_len(MAX_PLANT_FILE_BYTES + 1)
        .unwrap();
    for (path, words) in [
        (&zero, "not a regular file (a character device)"),
        (&fifo, "not a regular file (a FIFO)"),
        (&huge, "more than the 268435456"),
    ] {
        let err = load_err(path);
        assert!(matches!(err, PlantFileError::Read { .. }), "{err}");
        let text = err.to_string();
        assert!(
            text.contains(words) && text.contains(&*path.to_string_lossy()),
            "{text}"
        );
    }
    // A buffer beside the glTF file that is a FIFO.
    let (mut doc, _) = triangle();
    doc["buffers"][0]["uri"] = json!("fifo.glb");
    let path = write(dir.path(), "tri.gltf", &serde_json::to_vec(&doc).unwrap());
    let err = load_err(&path).to_string();
    assert!(err.contains("fifo.glb") && err.contains("a FIFO"), "{err}");
}

#[test]
fn text_that_is_not_gltf_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "notes.gltf", b"a fern, about knee high\n");
    assert!(matches!(load_err(&path), PlantFileError::NotGltf { .. }));
    // JSON, but not glTF (no asset).
    let path = write(dir.path(), "other.gltf", b"{\"meshes\": []}");
    assert!(matches!(load_err(&path), PlantFileError::NotGltf { .. }));
}

#[test]
fn a_mesh_without_position_is_no_mesh() {
    let dir = tempfile::tempdir().unwrap();
    let (mut doc, bin) = triangle();
    doc["meshes"][0]["primitives"][0]["attributes"] = json!({"COLOR_0": 1});
    let path = write(dir.path(), "nopos.glb", &glb(&doc, &bin));
    let err = load_err(&path);
    assert!(matches!(err, PlantFileError::NoMesh { .. }), "{err}");
    assert!(err.to_string().contains("POSITION"), "{err}");
}

#[test]
fn too_many_vertices_names_count_and_limit() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("huge.gltf");
    let count = MAX_PLANT_VERTICES + 1;
    let mesh = PlantMesh {
        vertices: (0..count)
            .map(|i| PlantVertex {
                position: [i as f32 * 1e-3, 0.0, 0.0],
                ..Default::default()
            })
            .collect(),
        indices: vec![0, 1, 2],
    };
    write_plant_gltf(&path, &mesh, None).unwrap();
    match load_err(&path) {
        PlantFileError::TooManyVertices {
            count: got, limit, ..
        } => {
            assert_eq!((got, limit), (count, MAX_PLANT_VERTICES));
        }
        other => panic!("{other:?}"),
    }
    assert!(load_err(&path).to_string().contains("65536"));
}

#[test]
fn too_many_triangles_names_count_and_limit() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("dense.gltf");
    let mut mesh = leaf();
    mesh.indices = [0, 1, 2].repeat(MAX_PLANT_TRIANGLES + 1);
    write_plant_gltf(&path, &mesh, None).unwrap();
    match load_err(&path) {
        PlantFileError::TooManyTriangles { count, limit, .. } => {
            assert_eq!(
                (count, limit),
                (MAX_PLANT_TRIANGLES + 1, MAX_PLANT_TRIANGLES)
            );
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn a_corrupt_base_colour_png_is_a_texture_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("leaf.gltf");
    write_plant_gltf(&path, &leaf(), Some(&image(2, 2))).unwrap();
    let png_path = dir.path().join("leaf_base_color.png");
    let mut bytes = std::fs::read(&png_path).unwrap();
    let len = bytes.len();
    bytes.truncate(len / 2);
    std::fs::write(&png_path, bytes).unwrap();
    match load_err(&path) {
        PlantFileError::Texture { texture, .. } => assert_eq!(texture, PlantTexture::BaseColor),
        other => panic!("{other:?}"),
    }
    // Missing altogether: the same error, naming the image file.
    std::fs::remove_file(&png_path).unwrap();
    let err = load_err(&path);
    assert!(matches!(err, PlantFileError::Texture { .. }), "{err}");
    assert!(err.to_string().contains("leaf_base_color.png"), "{err}");
}

#[test]
fn a_texture_over_the_size_limit_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let wide = image(MAX_TEXTURE_SIZE + 1, 1);
    let (doc, bin) = triangle_with_texture(&png(&wide));
    let path = write(dir.path(), "wide.glb", &glb(&doc, &bin));
    match load_err(&path) {
        PlantFileError::TextureTooLarge { width, height, .. } => {
            assert_eq!((width, height), (MAX_TEXTURE_SIZE + 1, 1))
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn indices_out_of_range_are_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let (doc, mut bin) = triangle();
    bin[52..54].copy_from_slice(&7u16.to_le_bytes());
    let path = write(dir.path(), "badindex.glb", &glb(&doc, &bin));
    match load_err(&path) {
        PlantFileError::IndexOutOfRange {
            index, vertices, ..
        } => assert_eq!((index, vertices), (7, 3)),
        other => panic!("{other:?}"),
    }
}

#[test]
fn missing_and_short_buffers_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let (mut doc, bin) = triangle();
    doc["buffers"][0]["uri"] = json!("tri.bin");
    let path = write(dir.path(), "tri.gltf", &serde_json::to_vec(&doc).unwrap());
    let err = load_err(&path);
    assert!(matches!(err, PlantFileError::BufferMissing { .. }), "{err}");
    assert!(err.to_string().contains("tri.bin"), "{err}");

    // Present beside the file: loads.
    write(dir.path(), "tri.bin", &bin);
    assert_eq!(load_plant(&path).unwrap().mesh.vertices.len(), 3);

    // Shorter than the glTF says.
    write(dir.path(), "tri.bin", &bin[..40]);
    assert!(matches!(
        load_err(&path),
        PlantFileError::BufferTooShort {
            len: 40,
            needed: 56,
            ..
        }
    ));

    // A .glb whose JSON promises more than its BIN chunk holds.
    let (mut doc, bin) = triangle();
    doc["buffers"][0]["byteLength"] = json!(4096);
    let path = write(dir.path(), "short.glb", &glb(&doc, &bin));
    assert!(matches!(
        load_err(&path),
        PlantFileError::BufferTooShort { needed: 4096, .. }
    ));
}

/// Loads `path` with a reader that counts the reads of each file.
fn load_counting(
    path: &Path,
) -> (
    Result<verdant::plants::LoadedPlant, PlantFileError>,
    std::collections::HashMap<PathBuf, usize>,
) {
    let reads = std::cell::RefCell::new(std::collections::HashMap::new());
    let result = verdant::plants::load_plant_from(path, &|p: &Path| {
        *reads.borrow_mut().entry(p.to_owned()).or_insert(0) += 1;
        verdant::plants::read_plant_file(p)
    });
    (result, reads.into_inner())
}

/// Buffers naming the same file are read once: a small file listing many of them cannot make
/// the loader read (and hold) a large file again and again.
#[test]
fn buffers_naming_one_file_read_it_once() {
    let dir = tempfile::tempdir().unwrap();
    let (mut doc, bin) = triangle();
    write(dir.path(), "tri.bin", &bin);
    doc["buffers"] = json!(vec![json!({"uri": "tri.bin", "byteLength": 56}); 20]);
    for view in 0..3 {
        doc["bufferViews"][view]["buffer"] = json!(view * 7);
    }
    let path = write(dir.path(), "tri.gltf", &serde_json::to_vec(&doc).unwrap());
    let (plant, reads) = load_counting(&path);
    assert_eq!(plant.unwrap().mesh.vertices.len(), 3);
    assert_eq!(
        reads.get(&dir.path().join("tri.bin")),
        Some(&1),
        "{reads:?}"
    );
}

/// The buffers of a plant together may hold at most MAX_PLANT_BUFFER_BYTES: declared larger,
/// the file is refused before a buffer is read; larger in their files than declared, once the
/// files read pass it.
#[test]
fn buffers_over_the_total_limit_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (mut doc, bin) = triangle();
    // Two files of the triangle's bytes followed by a sparse 130 MiB: 260 MiB together.
    for name in ["a.bin", "b.bin"] {
        let file = write(dir.path(), name, &bin);
        std::fs::File::options()
            .write(true)
            .open(&file)
            .unwrap()
            .set_len(130 << 20)
            .unwrap();
    }
    doc["buffers"] = json!([
        {"uri": "a.bin", "byteLength": 130 << 20},
        {"uri": "b.bin", "byteLength": 130 << 20},
    ]);
    for view in 1..3 {
        doc["bufferViews"][view]["buffer"] = json!(1);
    }
    let path = write(dir.path(), "big.gltf", &serde_json::to_vec(&doc).unwrap());
    let (result, reads) = load_counting(&path);
    let err = result.unwrap_err();
    assert!(
        matches!(err, PlantFileError::BuffersTooLarge { bytes, limit, .. }
            if bytes == 260 << 20 && limit == MAX_PLANT_BUFFER_BYTES),
        "{err}"
    );
    let text = err.to_string();
    assert!(
        text.contains("big.gltf") && text.contains(&MAX_PLANT_BUFFER_BYTES.to_string()),
        "{text}"
    );
    assert_eq!(reads.len(), 1, "only the glTF file is read: {reads:?}");

    // Declared small, the files hold the same: refused once the second is read.
    doc["buffers"][0]["byteLength"] = json!(56);
    doc["buffers"][1]["byteLength"] = json!(56);
    std::fs::write(&path, serde_json::to_vec(&doc).unwrap()).unwrap();
    let err = load_err(&path);
    assert!(
        matches!(err, PlantFileError::BuffersTooLarge { bytes, .. } if bytes == 260 << 20),
        "{err}"
    );

    // One of them alone is within the limit, and loads.
    doc["buffers"] = json!([{"uri": "a.bin", "byteLength": 56}]);
    for view in 0..3 {
        doc["bufferViews"][view]["buffer"] = json!(0);
    }
    std::fs::write(&path, serde_json::to_vec(&doc).unwrap()).unwrap();
    assert_eq!(load_plant(&path).unwrap().mesh.vertices.len(), 3);
}

/// Loads `path` with a reader that lists the files it is asked for.
fn load_listing(
    path: &Path,
) -> (
    Result<verdant::plants::LoadedPlant, PlantFileError>,
    Vec<PathBuf>,
) {
    let reads = std::cell::RefCell::new(Vec::new());
    let result = verdant::plants::load_plant_from(path, &|p: &Path| {
        reads.borrow_mut().push(p.to_owned());
        verdant::plants::read_plant_file(p)
    });
    (result, reads.into_inner())
}

/// A buffer or image is read from the glTF file's folder or below it, never through `..`
/// (percent-encoded or not), an absolute path, a scheme or a backslash: the URI is refused by
/// name before any file it names is asked for, whatever reads the files (disk or HTTP).
#[test]
fn uris_leaving_the_gltf_files_folder_are_refused_before_any_read() {
    let dir = tempfile::tempdir().unwrap();
    let plants = dir.path().join("world").join("plants");
    std::fs::create_dir_all(plants.join("sub")).unwrap();
    let (doc, bin) = triangle();
    let outside = write(dir.path(), "outside.bin", &bin);
    write(&dir.path().join("world"), "outside.bin", &bin);
    write(&plants.join("sub"), "tri.bin", &bin);
    let outside_png = png(&image(2, 2));
    write(&dir.path().join("world"), "outside.png", &outside_png);
    let path = plants.join("tri.gltf");

    let refused = [
        "../../outside.bin".to_owned(),
        "../outside.bin".into(),
        "..%2F..%2Foutside.bin".into(),
        "%2e%2e/%2E%2E/outside.bin".into(),
        "sub/../../outside.bin".into(),
        "sub/%2e%2e%2f%2e%2e/outside.bin".into(),
        "..".into(),
        "..\\outside.bin".into(),
        "..%5Coutside.bin".into(),
        "sub\\tri.bin".into(),
        outside.display().to_string(),
        format!("file://{}", outside.display()),
    ];
    for uri in &refused {
        let mut doc = doc.clone();
        doc["buffers"][0]["uri"] = json!(uri);
        std::fs::write(&path, serde_json::to_vec(&doc).unwrap()).unwrap();
        let (result, reads) = load_listing(&path);
        let err = result.expect_err(uri);
        assert!(matches!(err, PlantFileError::BadUri { .. }), "{uri}: {err}");
        let text = err.to_string();
        assert!(
            text.contains(&path.display().to_string()) && text.contains(&format!("{uri:?}")),
            "{text}"
        );
        assert_eq!(reads, std::slice::from_ref(&path), "{uri}");
    }

    // An image's URI, and a buffer no view uses, are checked too.
    let (mut textured, tbin) = triangle_with_texture(&outside_png);
    textured["buffers"][0]["uri"] = json!("sub/tex.bin");
    write(&plants.join("sub"), "tex.bin", &tbin);
    textured["images"] = json!([{"uri": "%2E%2E/outside.png"}]);
    std::fs::write(&path, serde_json::to_vec(&textured).unwrap()).unwrap();
    let (result, reads) = load_listing(&path);
    let err = result.unwrap_err();
    assert!(err.to_string().contains("%2E%2E/outside.png"), "{err}");
    assert_eq!(reads, std::slice::from_ref(&path));
    let mut unused = doc.clone();
    unused["buffers"][0]["uri"] = json!("sub/tri.bin");
    unused["buffers"]
        .as_array_mut()
        .unwrap()
        .push(json!({"uri": "../outside.bin", "byteLength": 56}));
    std::fs::write(&path, serde_json::to_vec(&unused).unwrap()).unwrap();
    let (result, reads) = load_listing(&path);
    assert!(matches!(result, Err(PlantFileError::BadUri { .. })));
    assert_eq!(reads, std::slice::from_ref(&path));

    // Files in the folder or below it, however spelt, load.
    for uri in [
        "sub/tri.bin",
        "./sub/tri.bin",
        "sub%2Ftri.bin",
        "%73ub/./tri.bin",
    ] {
        let mut doc = doc.clone();
        doc["buffers"][0]["uri"] = json!(uri);
        std::fs::write(&path, serde_json::to_vec(&doc).unwrap()).unwrap();
        let (result, _) = load_listing(&path);
        assert_eq!(result.expect(uri).mesh.vertices.len(), 3, "{uri}");
    }
    textured["images"] = json!([{"uri": "sub/..%2Fsub/x.png"}]);
    std::fs::write(&path, serde_json::to_vec(&textured).unwrap()).unwrap();
    assert!(matches!(
        load_listing(&path).0,
        Err(PlantFileError::BadUri { .. })
    ));
}

/// The JSON's bytes outside its strings' contents, whitespace left out (the loader's own count
/// is checked against this one).
fn json_structure(json: &[u8]) -> u64 {
    let text = std::str::from_utf8(json).unwrap();
    let mut count = 0;
    let mut chars = text.chars();
    while let Some(c) = chars.next() {
        match c {
            '"' => {
                count += 2;
                while let Some(c) = chars.next() {
                    match c {
                        '\\' => {
                            chars.next();
                        }
                        '"' => break,
                        _ => {}
                    }
                }
            }
            c if c.is_ascii_whitespace() => {}
            c => count += c.len_utf8() as u64,
        }
    }
    count
}

/// `doc` with a member the loader ignores, `"padding": [0,0,...]`, sized so that the JSON holds
/// `structure` bytes besides its strings and whitespace.
fn padded(doc: &Value, structure: u64) -> Vec<u8> {
    let mut doc = doc.clone();
    doc["padding"] = json!([]);
    let base = serde_json::to_vec(&doc).unwrap();
    let extra = structure - json_structure(&base);
    // "[]" becomes "[0]" (1 byte more) or "[10]" (2), and each ",0" after adds 2.
    let first = if extra % 2 == 1 { "0" } else { "10" };
    let mut items = first.to_owned();
    items.push_str(&",0".repeat(((extra - first.len() as u64) / 2) as usize));
    let text = String::from_utf8(base).unwrap();
    let json = text.replacen("\"padding\":[]", &format!("\"padding\":[{items}]"), 1);
    assert_eq!(json_structure(json.as_bytes()), structure);
    json.into_bytes()
}

/// A plant's JSON holds at most MAX_PLANT_JSON_BYTES besides its strings' contents and
/// whitespace, counted before it is parsed (parsed, a JSON of `{}` nodes takes some 64 times its
/// size); the data URIs of a .gltf and the BIN chunk of a .glb do not count.
#[test]
fn json_over_its_limit_is_refused_before_parsing() {
    use base64::Engine as _;
    use verdant::plants::MAX_PLANT_JSON_BYTES;
    let dir = tempfile::tempdir().unwrap();
    let (mut doc, bin) = triangle();
    let uri = |bytes: &[u8]| {
        format!(
            "data:application/octet-stream;base64,{}",
            base64::engine::general_purpose::STANDARD.encode(bytes)
        )
    };
    doc["buffers"][0]["uri"] = json!(uri(&bin));

    // At the limit: loads. One byte over: refused by name, size and limit.
    let path = write(dir.path(), "at.gltf", &padded(&doc, MAX_PLANT_JSON_BYTES));
    assert_eq!(load_plant(&path).unwrap().mesh.vertices.len(), 3);
    let path = write(
        dir.path(),
        "over.gltf",
        &padded(&doc, MAX_PLANT_JSON_BYTES + 1),
    );
    let err = load_err(&path);
    assert!(
        matches!(err, PlantFileError::JsonTooLarge { bytes, limit, .. }
            if bytes == MAX_PLANT_JSON_BYTES + 1 && limit == MAX_PLANT_JSON_BYTES),
        "{err}"
    );
    let text = err.to_string();
    assert!(
        text.contains(&format!("{}", MAX_PLANT_JSON_BYTES + 1))
            && text.contains(&format!("{MAX_PLANT_JSON_BYTES}")),
        "{text}"
    );

    // Not parsed: a document of empty nodes, cut short, is refused for its size rather than
    // as broken JSON.
    let nodes = MAX_PLANT_JSON_BYTES / 3 + 1;
    let mut cut = b"{\"nodes\":[".to_vec();
    cut.extend_from_slice(&b"{},".repeat(nodes as usize));
    let path = write(dir.path(), "nodes.gltf", &cut);
    assert!(
        matches!(load_err(&path), PlantFileError::JsonTooLarge { .. }),
        "{path:?}"
    );

    // Whitespace and strings do not count: a .gltf with a buffer of twice the limit in a data
    // URI, pretty-printed, loads.
    let mut big = bin.clone();
    big.resize(2 * MAX_PLANT_JSON_BYTES as usize, 0);
    let mut embedded = doc.clone();
    embedded["buffers"][0]["uri"] = json!(uri(&big));
    embedded["buffers"][0]["byteLength"] = json!(big.len());
    let text = serde_json::to_vec_pretty(&embedded).unwrap();
    assert!(text.len() as u64 > 2 * MAX_PLANT_JSON_BYTES);
    let path = write(dir.path(), "embedded.gltf", &text);
    assert_eq!(load_plant(&path).unwrap().mesh.vertices.len(), 3);

    // A .glb's JSON chunk likewise; its BIN chunk does not count.
    let (doc, bin) = triangle();
    let over: Value = serde_json::from_slice(&padded(&doc, MAX_PLANT_JSON_BYTES + 1)).unwrap();
    let path = write(dir.path(), "over.glb", &glb(&over, &bin));
    let err = load_err(&path);
    assert!(
        matches!(err, PlantFileError::JsonTooLarge { bytes, .. } if bytes == MAX_PLANT_JSON_BYTES + 1),
        "{err}"
    );
    let mut big_doc = doc.clone();
    big_doc["buffers"][0]["byteLength"] = json!(big.len());
    let path = write(dir.path(), "big_bin.glb", &glb(&big_doc, &big));
    assert_eq!(load_plant(&path).unwrap().mesh.vertices.len(), 3);
}

#[test]
fn a_node_cycle_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (mut doc, bin) = triangle();
    doc["nodes"][0]["children"] = json!([0]);
    let path = write(dir.path(), "cycle.glb", &glb(&doc, &bin));
    let err = load_err(&path);
    assert!(err.to_string().contains("cycle"), "{err}");

    // A cycle that fans out: a node listing another 20,000 times, which lists itself as often.
    // Refused as quickly, the nodes still to visit bounded too (they once grew by 20,000 a
    // visit, to gigabytes, before the count of visits was reached).
    let (mut doc, bin) = triangle();
    let fan: Vec<u32> = vec![1; 20_000];
    doc["nodes"][0]["children"] = json!(fan);
    doc["nodes"]
        .as_array_mut()
        .unwrap()
        .push(json!({ "children": fan }));
    let path = write(dir.path(), "fan.glb", &glb(&doc, &bin));
    let start = std::time::Instant::now();
    let err = load_err(&path);
    assert!(err.to_string().contains("cycle"), "{err}");
    assert!(
        start.elapsed() < std::time::Duration::from_secs(20),
        "refused only after {:?}",
        start.elapsed()
    );
}

#[test]
fn an_accessor_past_its_view_is_a_bad_primitive() {
    let dir = tempfile::tempdir().unwrap();
    let (mut doc, bin) = triangle();
    doc["accessors"][0]["count"] = json!(4);
    doc["accessors"][1]["count"] = json!(4);
    let path = write(dir.path(), "overrun.glb", &glb(&doc, &bin));
    let err = load_err(&path);
    assert!(matches!(err, PlantFileError::BadPrimitive { .. }), "{err}");
}

/// Loads a garbled file; the result may be anything but a panic.
fn load_garbled(path: &Path, bytes: &[u8]) -> bool {
    std::fs::write(path, bytes).unwrap();
    load_plant(path).is_ok()
}

#[test]
fn garbled_glb_files_never_panic() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("garbled.glb");
    let (doc, bin) = triangle_with_texture(&png(&image(2, 2)));
    let good = glb(&doc, &bin);
    assert!(load_garbled(&path, &good));
    let mut loaded = 0;
    for cut in 0..good.len() {
        assert!(!load_garbled(&path, &good[..cut]), "cut at {cut}");
    }
    for at in 0..good.len() {
        let original = good[at];
        let mut bytes = good.clone();
        let mut replacements = vec![0x00, 0xff, original ^ 0x5a];
        if original.is_ascii_digit() {
            // Numbers in the JSON: counts, offsets and indices far too large.
            replacements.push(b'9');
        }
        for r in replacements {
            bytes[at] = r;
            loaded += usize::from(load_garbled(&path, &bytes));
        }
    }
    // Bytes of colours and padding change nothing that matters: some garbled files still load.
    assert!(loaded > 0);
}

/// JSON pointers to every number and every object member under `value`.
fn pointers(value: &Value, at: String, numbers: &mut Vec<String>, members: &mut Vec<String>) {
    match value {
        Value::Number(_) => numbers.push(at),
        Value::Array(items) => {
            for (i, item) in items.iter().enumerate() {
                pointers(item, format!("{at}/{i}"), numbers, members);
            }
        }
        Value::Object(map) => {
            for (key, item) in map {
                let child = format!("{at}/{key}");
                members.push(child.clone());
                pointers(item, child, numbers, members);
            }
        }
        _ => {}
    }
}

#[test]
fn glb_files_with_wrong_numbers_or_missing_members_never_panic() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("mutated.glb");
    let (doc, bin) = triangle_with_texture(&png(&image(2, 2)));
    let (mut numbers, mut members) = (Vec::new(), Vec::new());
    pointers(&doc, String::new(), &mut numbers, &mut members);
    for pointer in &numbers {
        for replacement in [
            json!(0),
            json!(1),
            json!(2),
            json!(5),
            json!(255),
            json!(65_535),
            json!(4_294_967_295u64),
            json!(-1),
            json!(1e30),
            json!(0.5),
        ] {
            let mut mutated = doc.clone();
            *mutated.pointer_mut(pointer).unwrap() = replacement;
            load_garbled(&path, &glb(&mutated, &bin));
        }
    }
    for pointer in &members {
        let (parent, key) = pointer.rsplit_once('/').unwrap();
        let mut mutated = doc.clone();
        mutated
            .pointer_mut(parent)
            .and_then(Value::as_object_mut)
            .unwrap()
            .remove(key);
        load_garbled(&path, &glb(&mutated, &bin));
    }
    // The scene without its BIN chunk.
    load_garbled(&path, &glb(&doc, &[]));
}

/// A plant type named "marigold" (the default world's first type renamed) whose mesh is `file`.
fn marigold(file: &str) -> verdant::world::PlantType {
    let manifest =
        verdant::world::Manifest::from_path(&common::default_world().join("world.toml")).unwrap();
    let mut t = manifest.plant_types[0].clone();
    t.name = "marigold".into();
    t.mesh = file.into();
    t
}

/// The message of the error refusing the plant type "marigold" whose file `name` holds `mesh`,
/// after checking that it names the type, the file and `reason`.
fn refused_model(name: &str, mesh: &PlantMesh, reason: &str) -> String {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(name);
    write_plant_gltf(&path, mesh, None).unwrap();
    let Err(err) = verdant::plants::set::model(&marigold(name), dir.path()) else {
        panic!("the plant type of {name} must be refused");
    };
    let message = err.to_string();
    for needle in ["\"marigold\"", &path.display().to_string(), reason] {
        assert!(
            message.contains(needle),
            "{message:?} does not name {needle:?}"
        );
    }
    message
}

/// The case of `common::undrawable_plants` written to `name`.
fn undrawable(name: &str) -> (PlantMesh, &'static str) {
    let (_, mesh, reason) = common::undrawable_plants()
        .into_iter()
        .find(|(n, _, _)| *n == name)
        .unwrap();
    (mesh, reason)
}

#[test]
fn a_triangle_primitive_of_two_indices_is_refused_as_drawing_nothing() {
    let (mesh, reason) = undrawable("two_indices.gltf");
    refused_model("two_indices.gltf", &mesh, reason);
}

#[test]
fn a_mesh_whose_every_triangle_is_degenerate_is_refused() {
    let (mesh, reason) = undrawable("degenerate.gltf");
    let message = refused_model("degenerate.gltf", &mesh, reason);
    assert!(message.contains("3 triangles"), "{message}");
    // One triangle with an area among degenerate ones is a plant.
    let dir = tempfile::tempdir().unwrap();
    let mesh = common::small_plant_indexed(&[0, 0, 0, 1, 1, 1, 0, 1, 2]);
    write_plant_gltf(&dir.path().join("one.gltf"), &mesh, None).unwrap();
    verdant::plants::set::model(&marigold("one.gltf"), dir.path()).unwrap();
}

#[test]
fn a_mesh_that_overflows_once_scaled_to_unit_height_is_refused() {
    let (mesh, reason) = undrawable("overflowing.gltf");
    refused_model("overflowing.gltf", &mesh, reason);
}

#[test]
fn a_mesh_far_wider_than_high_is_refused() {
    let (mesh, reason) = undrawable("wide.gltf");
    refused_model("wide.gltf", &mesh, reason);
    // 2e6 m wide and 1 m high: refused; 40 m wide and 1 m high (a reach of 20 times the
    // height): a plant.
    let dir = tempfile::tempdir().unwrap();
    let mesh = common::small_plant_moved(|[x, y, z]| [x / 0.3 * 20.0, y, z]);
    write_plant_gltf(&dir.path().join("creeping.gltf"), &mesh, None).unwrap();
    let model = verdant::plants::set::model(&marigold("creeping.gltf"), dir.path()).unwrap();
    assert!(
        (model.radius_ratio - 20.0).abs() < 1e-3,
        "{}",
        model.radius_ratio
    );
}

#[test]
fn a_heavy_plant_gets_a_reduced_level_and_a_nearer_switch() {
    use verdant::plants::set::{FILE_REDUCED_TRIANGLES, FULL_MESH_TRIANGLE_BUDGET};
    let dir = tempfile::tempdir().unwrap();
    let heavy = common::heavy_plant();
    write_plant_gltf(&dir.path().join("heavy.gltf"), &heavy, None).unwrap();
    let t = marigold("heavy.gltf");
    let model = verdant::plants::set::model(&t, dir.path()).unwrap();
    let [full, reduced, _] = &model.lods;
    assert_eq!(full.triangles(), 130_050);
    assert!(
        (FILE_REDUCED_TRIANGLES / 4..=FILE_REDUCED_TRIANGLES).contains(&reduced.triangles()),
        "{} triangles",
        reduced.triangles()
    );
    // The same plant, coarser: its height and reach, and vertices of the full mesh.
    assert!((reduced.height() / full.height() - 1.0).abs() < 0.15);
    assert!((reduced.radius() / full.radius() - 1.0).abs() < 0.2);
    assert!(reduced.vertices.iter().all(|v| full.vertices.contains(v)));
    // Its full meshes at the type's highest density within the reach make the budget.
    let density = t.density.values().copied().fold(0.0f32, f32::max);
    let r = model.full_mesh_reach_m;
    let triangles = std::f32::consts::PI * r * r * density * 130_050.0;
    assert!(
        (triangles / FULL_MESH_TRIANGLE_BUDGET - 1.0).abs() < 1e-3,
        "{r} m: {triangles}"
    );
    assert!(r < 10.0, "{r}");

    // A light plant keeps its mesh at both levels and the settings' switch.
    write_plant_gltf(&dir.path().join("light.gltf"), &common::small_plant(), None).unwrap();
    let model = verdant::plants::set::model(&marigold("light.gltf"), dir.path()).unwrap();
    assert_eq!(model.lods[0], model.lods[1]);
    assert!(
        model.full_mesh_reach_m > 150.0,
        "{}",
        model.full_mesh_reach_m
    );
}
