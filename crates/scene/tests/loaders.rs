//! Loader tests on the real assets in `shared/assets` (beside the repository): triangle and
//! point counts from MANIFEST.md, glTF material mapping, and every file of `broken-models/`.

use std::path::{Path, PathBuf};

use hybrid_scene::load::{load_model, load_point_cloud, load_texture};
use hybrid_scene::{ColorSpace, Material, Mesh, SceneError, Texture};

const ASSETS: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/assets");

fn asset(rel: &str) -> PathBuf {
    Path::new(ASSETS).join(rel)
}

struct Model {
    meshes: Vec<Mesh>,
    materials: Vec<Material>,
    textures: Vec<Texture>,
}

impl Model {
    fn triangles(&self) -> usize {
        self.meshes.iter().map(|m| m.indices.len()).sum()
    }
    fn vertices(&self) -> usize {
        self.meshes.iter().map(|m| m.positions.len()).sum()
    }
}

#[allow(clippy::result_large_err)] // SceneError is the API's error type
fn model(rel: &str) -> Result<Model, SceneError> {
    let (mut materials, mut textures) = (Vec::new(), Vec::new());
    let meshes = load_model(&asset(rel), &mut materials, &mut textures)?;
    Ok(Model { meshes, materials, textures })
}

fn ok_model(rel: &str) -> Model {
    let m = model(rel).unwrap_or_else(|e| panic!("{rel} should load: {e}"));
    check_sane(rel, &m);
    m
}

/// Invariants every loaded model must satisfy.
fn check_sane(rel: &str, m: &Model) {
    assert!(!m.materials.is_empty(), "{rel}: at least one material is appended");
    for (i, mesh) in m.meshes.iter().enumerate() {
        let n = mesh.positions.len();
        assert!(mesh.material < m.materials.len(), "{rel} mesh {i}: material index");
        for (name, len) in
            [("normals", mesh.normals.len()), ("uvs", mesh.uvs.len()), ("tangents", mesh.tangents.len()), ("colors", mesh.colors.len())]
        {
            assert!(len == 0 || len == n, "{rel} mesh {i}: {name} has {len} entries for {n} vertices");
        }
        assert!(mesh.indices.iter().flatten().all(|&v| (v as usize) < n), "{rel} mesh {i}: index out of range");
        assert!(mesh.positions.iter().all(|p| p.is_finite()), "{rel} mesh {i}: non-finite position");
        for mat in &m.materials {
            for t in [mat.diffuse_map, mat.normal_map, mat.emission_map, mat.ambient_map, mat.specular_map].into_iter().flatten() {
                assert!(t < m.textures.len(), "{rel}: material {} texture {t} out of range", mat.name);
            }
        }
    }
}

/// The load fails cleanly and the message names the file.
fn assert_model_err(rel: &str) -> SceneError {
    let e = match model(rel) {
        Ok(m) => panic!("{rel} should be rejected, but loaded {} meshes / {} triangles", m.meshes.len(), m.triangles()),
        Err(e) => e,
    };
    let file = Path::new(rel).file_name().unwrap().to_string_lossy().into_owned();
    assert!(e.to_string().contains(&file), "{rel}: error does not name the file: {e}");
    assert!(!e.message.is_empty());
    e
}

// ---------------------------------------------------------------------------------------------
// Counts from MANIFEST.md

#[test]
fn sponza_obj_triangles_materials_and_textures() {
    let m = ok_model("sponza-dabrovic/sponza_dabrovic.obj");
    assert_eq!(m.triangles(), 66_445);
    assert_eq!(m.meshes.len(), 37);
    assert!(m.materials.len() >= 19, "{} materials", m.materials.len());
    assert!(m.textures.len() >= 10, "{} textures", m.textures.len());
    let textured = m.materials.iter().filter(|x| x.diffuse_map.is_some()).count();
    assert!(textured >= 10, "{textured} textured materials");
    // Ka is absent in this MTL: ambient shows the diffuse colour.
    assert!(m.materials.iter().all(|x| x.ambient == x.diffuse));
    assert!(m.textures.iter().all(|t| t.color_space == ColorSpace::Srgb));
}

#[test]
fn bunny_obj_triangles() {
    let m = ok_model("stanford-bunny/stanford-bunny.obj");
    assert_eq!(m.triangles(), 69_451);
    assert_eq!(m.materials.len(), 1, "no MTL: one default material");
}

#[test]
fn dragon_ply_triangles() {
    let m = ok_model("stanford-dragon/dragon_vrip.ply");
    assert_eq!(m.triangles(), 871_414);
    assert_eq!(m.vertices(), 437_645);
    let r = ok_model("stanford-dragon/dragon_vrip_res2.ply");
    assert_eq!(r.triangles(), 202_520);
}

#[test]
fn armadillo_ply_and_obj_triangles() {
    assert_eq!(ok_model("stanford-armadillo/armadillo_flex_30k.ply").triangles(), 30_000);
    assert_eq!(ok_model("stanford-armadillo/armadillo_100k.obj").triangles(), 99_976);
}

#[test]
fn breakfast_room_glb_triangles() {
    let m = ok_model("dining-room-breakfast-room/breakfast_room.glb");
    assert_eq!(m.triangles(), 269_538);
    assert_eq!(m.meshes.len(), 53);
    assert_eq!(m.materials.len(), 15);
    assert!(!m.textures.is_empty());
}

#[test]
fn barcelona_pavilion_glb_triangles_and_transmission() {
    let m = ok_model("barcelona-pavilion-outdoor/barcelona_pavilion.glb");
    assert_eq!(m.triangles(), 133_575);
    assert_eq!(m.meshes.len(), 106);
    assert_eq!(m.materials.len(), 17);
    let refractive: Vec<&Material> = m.materials.iter().filter(|x| x.opacity < 1.0).collect();
    assert_eq!(refractive.len(), 2, "glass and water");
    let mut iors: Vec<f32> = refractive.iter().map(|x| x.ior).collect();
    iors.sort_by(f32::total_cmp);
    assert!((iors[0] - 1.33).abs() < 1e-4 && (iors[1] - 1.5).abs() < 1e-4, "{iors:?}");
    // Aluminium (metallic 1) is a reflective material.
    assert!(m.materials.iter().any(|x| x.reflectivity > 0.0));
    // Every normal-mapped mesh has tangents (from the file or computed).
    for mesh in &m.meshes {
        if m.materials[mesh.material].normal_map.is_some() && !mesh.uvs.is_empty() && !mesh.normals.is_empty() {
            assert_eq!(mesh.tangents.len(), mesh.positions.len());
        }
    }
}

#[test]
fn tree_ply_point_cloud() {
    let (points, colors) = load_point_cloud(&asset("tree-pointcloud/rtls_tls_scan_1m.ply")).unwrap();
    assert_eq!(points.len(), 1_046_843);
    assert!(colors.is_empty(), "the scan has no colours");
    let (p2, _) = load_point_cloud(&asset("tree-pointcloud/rtls_pc_tree.ply")).unwrap();
    assert_eq!(p2.len(), 75_848);
}

#[test]
fn las_and_laz_have_the_same_points() {
    let (a, ca) = load_point_cloud(&asset("tree-pointcloud/treels_pine.las")).unwrap();
    let (b, cb) = load_point_cloud(&asset("tree-pointcloud/treels_pine.laz")).unwrap();
    assert_eq!(a.len(), 73_851);
    assert_eq!(b.len(), 73_851);
    assert_eq!(a, b);
    assert!(ca.is_empty() && cb.is_empty(), "point format 0 has no colours");
    assert!(a.iter().all(|p| p.is_finite()));
}

#[test]
fn textures_decode_and_bad_ones_name_the_file() {
    let t = load_texture(&asset("barcelona-pavilion-outdoor/textures/rocks.png"), ColorSpace::Srgb).unwrap();
    assert!(t.width() > 1 && t.height() > 1);
    assert_eq!(t.levels.last().map(|l| (l.width, l.height)), Some((1, 1)));
    let e = load_texture(&asset("barcelona-pavilion-outdoor/textures/skylight-morn.exr"), ColorSpace::Linear).unwrap_err();
    assert!(e.to_string().contains("skylight-morn.exr"), "{e}");
    let e = load_texture(&asset("stanford-bunny/LICENSE-NOTE.md"), ColorSpace::Srgb).unwrap_err();
    assert!(e.to_string().contains("LICENSE-NOTE.md"), "{e}");
}

#[test]
fn point_cloud_of_a_non_point_file_is_an_error() {
    let e = load_point_cloud(&asset("stanford-bunny/stanford-bunny.obj")).unwrap_err();
    assert!(e.to_string().contains("stanford-bunny.obj") && e.message.contains(".obj"), "{e}");
}

// ---------------------------------------------------------------------------------------------
// broken-models/gltf

#[test]
fn gltf_index_out_of_range() {
    let e = assert_model_err("broken-models/gltf/IndexOutOfRange/IndexOutOfRange.gltf");
    assert!(e.message.contains("index"), "{e}");
}

#[test]
fn gltf_all_indices_out_of_range() {
    assert_model_err("broken-models/gltf/IndexOutOfRange/AllIndicesOutOfRange.gltf");
}

#[test]
fn gltf_incorrect_vertex_arrays() {
    assert_model_err("broken-models/gltf/IncorrectVertexArrays/Cube.gltf");
}

#[test]
fn gltf_missing_bin() {
    assert_model_err("broken-models/gltf/MissingBin/BoxTextured.gltf");
}

#[test]
fn gltf_recursive_nodes() {
    let e = assert_model_err("broken-models/gltf/RecursiveNodes/RecursiveNodes.gltf");
    assert!(e.message.contains("cycle"), "{e}");
}

#[test]
fn gltf_scene_wrong_type() {
    assert_model_err("broken-models/gltf/SchemaFailures/sceneWrongType.gltf");
}

#[test]
fn gltf_no_scene() {
    assert_model_err("broken-models/gltf/TestNoRootNode/NoScene.gltf");
}

#[test]
fn gltf_scene_without_nodes_is_empty_but_valid() {
    let m = ok_model("broken-models/gltf/TestNoRootNode/SceneWithoutNodes.gltf");
    assert_eq!(m.meshes.len(), 0);
    assert_eq!(m.materials.len(), 1, "a file without materials gets one default material");
}

#[test]
fn gltf_wrong_types() {
    for f in ["badArray", "badExtension", "badNumber", "badObject", "badString", "badUint"] {
        assert_model_err(&format!("broken-models/gltf/wrongTypes/{f}.gltf"));
    }
}

#[test]
fn gltf_box_bad_normals_loads() {
    let m = ok_model("broken-models/gltf/BoxBadNormals.glb");
    assert_eq!(m.triangles(), 12);
    for mesh in &m.meshes {
        assert!(mesh.normals.iter().all(|n| n.is_finite() && (n.length() < 1e-6 || (n.length() - 1.0).abs() < 1e-4)));
    }
}

#[test]
fn gltf_box_with_infinites() {
    assert_model_err("broken-models/gltf/BoxWithInfinites.glb");
}

#[test]
fn gltf_truncated_glb() {
    assert_model_err("broken-models/gltf/truncated_BoxTextured.glb");
}

#[test]
fn gltf_bad_magic() {
    assert_model_err("broken-models/gltf/bad_magic_BoxTextured.glb");
}

#[test]
fn gltf_control_valid_box_textured() {
    let m = ok_model("broken-models/gltf/control-valid-BoxTextured/BoxTextured.glb");
    assert_eq!(m.triangles(), 12);
    assert_eq!(m.vertices(), 24);
    assert_eq!(m.textures.len(), 1);
    let mat = &m.materials[m.meshes[0].material];
    assert_eq!(mat.diffuse_map, Some(0));
    assert_eq!(m.textures[0].color_space, ColorSpace::Srgb);
    assert_eq!(mat.opacity, 1.0);
}

// ---------------------------------------------------------------------------------------------
// broken-models/obj

#[test]
fn obj_malformed() {
    assert_model_err("broken-models/obj/malformed.obj");
}

#[test]
fn obj_malformed2_empty_face() {
    let e = assert_model_err("broken-models/obj/malformed2.obj");
    assert!(e.message.contains("without vertices") && e.location.is_some(), "{e}");
}

#[test]
fn obj_empty() {
    assert_model_err("broken-models/obj/empty.obj");
}

#[test]
fn obj_face_index_out_of_range() {
    assert_model_err("broken-models/obj/face_index_out_of_range.obj");
}

#[test]
fn obj_truncated_mid_line() {
    assert_model_err("broken-models/obj/truncated_mid_line.obj");
}

#[test]
fn obj_box_without_lineending() {
    let m = ok_model("broken-models/obj/box_without_lineending.obj");
    assert_eq!(m.triangles(), 12);
}

#[test]
fn obj_box_utf16be() {
    let e = assert_model_err("broken-models/obj/box_UTF16BE.obj");
    assert!(e.message.contains("UTF-16"), "{e}");
}

#[test]
fn obj_number_formats() {
    let m = ok_model("broken-models/obj/number_formats.obj");
    assert_eq!(m.triangles(), 1);
    // `f 1 2 4` uses (0,0,0), (1,2,3) and (-1,-2,-3).
    assert!(m.meshes[0].positions.contains(&glam::Vec3::new(-1.0, -2.0, -3.0)));
}

#[test]
fn obj_multiple_spaces() {
    let m = ok_model("broken-models/obj/multiple_spaces.obj");
    assert!(m.triangles() >= 1);
}

#[test]
fn obj_concave_polygon_is_triangulated_inside_the_outline() {
    let m = ok_model("broken-models/obj/concave_polygon.obj");
    assert_eq!(m.triangles(), 64);
    // Ear clipping: the triangles' areas add up to the polygon's (a fan of a concave polygon
    // overlaps itself and its triangles' areas exceed it).
    let mesh = &m.meshes[0];
    let area = |t: &[u32; 3]| {
        let p = t.map(|i| mesh.positions[i as usize]);
        (p[1] - p[0]).cross(p[2] - p[0]).length() * 0.5
    };
    let sum: f32 = mesh.indices.iter().map(area).sum();
    // The polygon's area from the file (Newell's formula over the face's outline, in file order).
    let text = std::fs::read_to_string(asset("broken-models/obj/concave_polygon.obj")).unwrap();
    let verts: Vec<glam::Vec3> = text
        .lines()
        .filter_map(|l| l.strip_prefix("v "))
        .map(|l| {
            let c: Vec<f32> = l.split_whitespace().map(|w| w.parse().unwrap()).collect();
            glam::Vec3::new(c[0], c[1], c[2])
        })
        .collect();
    let face: Vec<usize> = text
        .lines()
        .find_map(|l| l.strip_prefix("f "))
        .unwrap()
        .split_whitespace()
        .map(|w| w.split('/').next().unwrap().parse::<usize>().unwrap() - 1)
        .collect();
    let mut newell = glam::Vec3::ZERO;
    for i in 0..face.len() {
        newell += verts[face[i]].cross(verts[face[(i + 1) % face.len()]]);
    }
    let poly = newell.length() * 0.5;
    assert!((sum - poly).abs() <= 1e-3 * poly, "triangles {sum} vs polygon {poly}");
}

#[test]
fn obj_point_cloud_has_no_faces() {
    let e = assert_model_err("broken-models/obj/point_cloud.obj");
    assert!(e.message.contains("no faces"), "{e}");
}

#[test]
fn obj_lines_only() {
    let e = assert_model_err("broken-models/obj/testline.obj");
    assert!(e.message.contains("no faces"), "{e}");
}

#[test]
fn obj_empty_material_name_falls_back_to_default() {
    let m = ok_model("broken-models/obj/empty_mat.obj");
    assert!(m.triangles() >= 1);
    // The MTL's only material has an empty name and Kd 0.8; `usemtl` (empty) selects it.
    let mat = &m.materials[m.meshes.last().unwrap().material];
    assert_eq!(mat.name, "");
    assert_eq!(mat.diffuse, glam::Vec3::splat(0.8));
}

// ---------------------------------------------------------------------------------------------
// broken-models/ply

#[test]
fn ply_empty() {
    assert_model_err("broken-models/ply/empty.ply");
    assert!(load_point_cloud(&asset("broken-models/ply/empty.ply")).is_err());
}

#[test]
fn ply_truncated_binary() {
    let e = assert_model_err("broken-models/ply/truncated_binary_dragon_res4.ply");
    assert!(e.message.contains("face"), "{e}");
}

#[test]
fn ply_truncated_header_only_fails_without_allocating_the_declared_sizes() {
    let e = assert_model_err("broken-models/ply/truncated_header_only.ply");
    assert!(e.message.contains("vertex 0 of 35947"), "{e}");
    let e = load_point_cloud(&asset("broken-models/ply/truncated_header_only.ply")).unwrap_err();
    assert!(e.to_string().contains("truncated_header_only.ply"), "{e}");
}

#[test]
fn ply_truncated_no_end_header() {
    assert_model_err("broken-models/ply/truncated_no_end_header.ply");
    assert!(load_point_cloud(&asset("broken-models/ply/truncated_no_end_header.ply")).is_err());
}

#[test]
fn ply_face_index_out_of_range() {
    let e = assert_model_err("broken-models/ply/face_index_out_of_range.ply");
    assert!(e.message.contains("99"), "{e}");
}

#[test]
fn ply_nan_inf_vertices() {
    assert_model_err("broken-models/ply/nan_inf_vertices.ply");
    assert!(load_point_cloud(&asset("broken-models/ply/nan_inf_vertices.ply")).is_err());
}

#[test]
fn ply_cube_binary() {
    let m = ok_model("broken-models/ply/cube_binary.ply");
    assert_eq!((m.vertices(), m.triangles()), (8, 12));
}

#[test]
fn ply_points_only_is_a_point_cloud_not_a_model() {
    let e = assert_model_err("broken-models/ply/points.ply");
    assert!(e.message.contains("has no faces (use it as a point cloud)"), "{e}");
    let (p, c) = load_point_cloud(&asset("broken-models/ply/points.ply")).unwrap();
    assert_eq!(p.len(), 4);
    assert_eq!(c, vec![[255, 255, 255], [255, 0, 255], [255, 255, 0], [0, 255, 255]]);
    assert_eq!(p[1], glam::Vec3::new(0.0, 0.0, 1.0));
}

#[test]
fn ply_float_colors() {
    let m = ok_model("broken-models/ply/float-color.ply");
    assert_eq!((m.vertices(), m.triangles()), (3, 1));
    assert_eq!(m.meshes[0].colors, vec![glam::Vec3::Z; 3]);
    let (_, c) = load_point_cloud(&asset("broken-models/ply/float-color.ply")).unwrap();
    assert_eq!(c, vec![[0, 0, 255]; 3]);
}

#[test]
fn ply_issue623_vertex_list_without_faces_loads_as_points() {
    // A `vertex_indices` list declared inside the vertex element, no data for it, no faces.
    let e = assert_model_err("broken-models/ply/issue623.ply");
    assert!(e.message.contains("no faces"), "{e}");
    let (p, c) = load_point_cloud(&asset("broken-models/ply/issue623.ply")).unwrap();
    assert_eq!(p.len(), 24);
    assert!(c.is_empty());
    assert_eq!(p[0], glam::Vec3::new(7.941797, 1.432409, -0.927566));
}

// ---------------------------------------------------------------------------------------------
// Truncation sweep: every prefix of small valid files loads or fails cleanly (never panics), and
// a failure names the file.

fn truncation_sweep(rel: &str, step: usize, point_cloud: bool) {
    let bytes = std::fs::read(asset(rel)).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let name = Path::new(rel).file_name().unwrap();
    let path = dir.path().join(name);
    for cut in (0..bytes.len()).step_by(step) {
        std::fs::write(&path, &bytes[..cut]).unwrap();
        let result = if point_cloud {
            load_point_cloud(&path).map(|(p, _)| p.len())
        } else {
            let (mut m, mut t) = (Vec::new(), Vec::new());
            load_model(&path, &mut m, &mut t).map(|meshes| meshes.len())
        };
        if let Err(e) = result {
            assert!(e.to_string().contains(&*name.to_string_lossy()), "{rel} cut at {cut}: {e}");
        }
    }
}

#[test]
fn truncated_prefixes_never_panic() {
    truncation_sweep("broken-models/ply/cube_binary.ply", 1, false);
    truncation_sweep("broken-models/ply/points.ply", 1, true);
    truncation_sweep("broken-models/obj/box_without_lineending.obj", 1, false);
    truncation_sweep("broken-models/gltf/control-valid-BoxTextured/BoxTextured.glb", 7, false);
    truncation_sweep("broken-models/ply/issue623.ply", 5, false);
}
