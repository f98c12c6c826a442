//! Geometry: procedural meshes (box, sphere, plane, cylinder, thin rod) and
//! glTF files (crate `gltf`). Meshes are built once, in object space, with
//! normals and UVs for the procedural textures.

use std::f32::consts::{PI, TAU};
use std::path::Path;

use bytemuck::{Pod, Zeroable};
use glam::{Mat3, Mat4, Vec3};
use serde::{Deserialize, Serialize};

use super::SceneError;

/// A mesh vertex as the GPU reads it.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct Vertex {
    /// Object-space position.
    pub position: [f32; 3],
    /// Object-space unit normal.
    pub normal: [f32; 3],
    /// Texture coordinate (world-unit scale for procedural shapes).
    pub uv: [f32; 2],
}

/// Indexed triangles.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    /// Vertices.
    pub vertices: Vec<Vertex>,
    /// Triangle list, counter-clockwise front faces.
    pub indices: Vec<u32>,
}

/// A mesh declaration in a scene file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub enum MeshSpec {
    /// Axis-aligned box centred on the origin.
    Box {
        /// Edge lengths.
        size: [f32; 3],
    },
    /// UV sphere centred on the origin.
    Sphere {
        /// Radius.
        radius: f32,
        /// Segments around (rings are half as many).
        #[serde(default = "default_segments")]
        segments: u32,
    },
    /// Horizontal plane (facing +Y) centred on the origin.
    Plane {
        /// Extent along x and z.
        size: [f32; 2],
    },
    /// Vertical capped cylinder centred on the origin.
    Cylinder {
        /// Radius.
        radius: f32,
        /// Height.
        height: f32,
        /// Segments around.
        #[serde(default = "default_segments")]
        segments: u32,
    },
    /// A thin vertical rod (a cylinder with few segments): fences, wires.
    Rod {
        /// Length.
        length: f32,
        /// Radius.
        radius: f32,
    },
    /// Every mesh of a glTF file's default scene, with node transforms.
    Gltf {
        /// Path, relative to the scene file's directory, or `builtin:NAME`
        /// for an asset embedded in the binary.
        path: String,
    },
}

fn default_segments() -> u32 {
    32
}

impl MeshSpec {
    /// Checks sizes and counts.
    pub fn validate(&self) -> Result<(), String> {
        let positive = |v: &[f32]| v.iter().all(|x| x.is_finite() && *x > 0.0);
        let ok = match self {
            MeshSpec::Box { size } => positive(size),
            MeshSpec::Sphere { radius, segments } => {
                positive(&[*radius]) && (3..=512).contains(segments)
            }
            MeshSpec::Plane { size } => positive(size),
            MeshSpec::Cylinder {
                radius,
                height,
                segments,
            } => positive(&[*radius, *height]) && (3..=512).contains(segments),
            MeshSpec::Rod { length, radius } => positive(&[*length, *radius]),
            MeshSpec::Gltf { path } => !path.is_empty(),
        };
        if ok {
            Ok(())
        } else {
            Err("sizes must be finite and > 0, segments in 3..=512, paths non-empty".into())
        }
    }

    /// Builds the triangles. `base` resolves relative glTF paths.
    pub fn build(&self, base: &Path) -> Result<Mesh, SceneError> {
        Ok(match self {
            MeshSpec::Box { size } => cuboid(Vec3::from(*size)),
            MeshSpec::Sphere { radius, segments } => sphere(*radius, *segments),
            MeshSpec::Plane { size } => plane(size[0], size[1]),
            MeshSpec::Cylinder {
                radius,
                height,
                segments,
            } => cylinder(*radius, *height, *segments),
            MeshSpec::Rod { length, radius } => cylinder(*radius, *length, 6),
            MeshSpec::Gltf { path } => match path.strip_prefix("builtin:") {
                Some(name) => {
                    let bytes = super::builtin::asset(name).ok_or_else(|| SceneError::Gltf {
                        path: path.clone(),
                        message: "no such built-in asset".into(),
                    })?;
                    let imported = gltf::import_slice(bytes).map_err(|e| SceneError::Gltf {
                        path: path.clone(),
                        message: e.to_string(),
                    })?;
                    gltf_mesh(path, imported)?
                }
                None => {
                    let full = base.join(path);
                    let imported = gltf::import(&full).map_err(|e| SceneError::Gltf {
                        path: full.display().to_string(),
                        message: e.to_string(),
                    })?;
                    gltf_mesh(&full.display().to_string(), imported)?
                }
            },
        })
    }
}

impl Mesh {
    fn push_quad(&mut self, corners: [Vec3; 4], normal: Vec3, uv_size: (f32, f32)) {
        let base = self.vertices.len() as u32;
        let uvs = [
            [0.0, 0.0],
            [uv_size.0, 0.0],
            [uv_size.0, uv_size.1],
            [0.0, uv_size.1],
        ];
        for (p, uv) in corners.iter().zip(uvs) {
            self.vertices.push(Vertex {
                position: p.to_array(),
                normal: normal.to_array(),
                uv,
            });
        }
        self.indices
            .extend([base, base + 1, base + 2, base, base + 2, base + 3]);
    }

    /// Object-space bounding box (min, max).
    pub fn bounds(&self) -> (Vec3, Vec3) {
        self.vertices.iter().fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), v| {
                (
                    lo.min(Vec3::from(v.position)),
                    hi.max(Vec3::from(v.position)),
                )
            },
        )
    }
}

/// A box with one quad per face; UVs in world units.
fn cuboid(size: Vec3) -> Mesh {
    let h = size * 0.5;
    let mut m = Mesh::default();
    // (normal, u axis, v axis) per face; corners = n·h ± u·h ± v·h.
    let faces = [
        (Vec3::X, Vec3::NEG_Z, Vec3::Y),
        (Vec3::NEG_X, Vec3::Z, Vec3::Y),
        (Vec3::Y, Vec3::X, Vec3::NEG_Z),
        (Vec3::NEG_Y, Vec3::X, Vec3::Z),
        (Vec3::Z, Vec3::X, Vec3::Y),
        (Vec3::NEG_Z, Vec3::NEG_X, Vec3::Y),
    ];
    for (n, u, v) in faces {
        let (c, du, dv) = (n * h, u * h, v * h);
        let (su, sv) = ((u * size).length(), (v * size).length());
        m.push_quad(
            [c - du - dv, c + du - dv, c + du + dv, c - du + dv],
            n,
            (su, sv),
        );
    }
    m
}

/// A horizontal plane facing +Y; UVs in world units.
fn plane(sx: f32, sz: f32) -> Mesh {
    let (hx, hz) = (sx * 0.5, sz * 0.5);
    let mut m = Mesh::default();
    m.push_quad(
        [
            Vec3::new(-hx, 0.0, hz),
            Vec3::new(hx, 0.0, hz),
            Vec3::new(hx, 0.0, -hz),
            Vec3::new(-hx, 0.0, -hz),
        ],
        Vec3::Y,
        (sx, sz),
    );
    m
}

/// A UV sphere.
fn sphere(radius: f32, segments: u32) -> Mesh {
    let rings = (segments / 2).max(2);
    let mut m = Mesh::default();
    for r in 0..=rings {
        let v = r as f32 / rings as f32;
        let theta = v * PI;
        for s in 0..=segments {
            let u = s as f32 / segments as f32;
            let phi = u * TAU;
            let n = Vec3::new(
                theta.sin() * phi.cos(),
                theta.cos(),
                -theta.sin() * phi.sin(),
            );
            m.vertices.push(Vertex {
                position: (n * radius).to_array(),
                normal: n.to_array(),
                uv: [u * TAU * radius, v * PI * radius],
            });
        }
    }
    let row = segments + 1;
    for r in 0..rings {
        for s in 0..segments {
            let (a, b) = (r * row + s, (r + 1) * row + s);
            m.indices.extend([a, b, a + 1, a + 1, b, b + 1]);
        }
    }
    m
}

/// A vertical capped cylinder.
fn cylinder(radius: f32, height: f32, segments: u32) -> Mesh {
    let h = height * 0.5;
    let mut m = Mesh::default();
    for s in 0..=segments {
        let u = s as f32 / segments as f32;
        let a = u * TAU;
        let n = Vec3::new(a.cos(), 0.0, -a.sin());
        for y in [-h, h] {
            m.vertices.push(Vertex {
                position: (n * radius + Vec3::Y * y).to_array(),
                normal: n.to_array(),
                uv: [u * TAU * radius, y + h],
            });
        }
    }
    for s in 0..segments {
        let a = 2 * s;
        m.indices.extend([a, a + 2, a + 1, a + 1, a + 2, a + 3]);
    }
    for (y, n) in [(h, Vec3::Y), (-h, Vec3::NEG_Y)] {
        let centre = m.vertices.len() as u32;
        m.vertices.push(Vertex {
            position: [0.0, y, 0.0],
            normal: n.to_array(),
            uv: [0.0, 0.0],
        });
        for s in 0..=segments {
            let a = s as f32 / segments as f32 * TAU;
            m.vertices.push(Vertex {
                position: [a.cos() * radius, y, -a.sin() * radius],
                normal: n.to_array(),
                uv: [a.cos() * radius, a.sin() * radius],
            });
        }
        for s in 0..segments {
            let (p, q) = (centre + 1 + s, centre + 2 + s);
            if y > 0.0 {
                m.indices.extend([centre, p, q]);
            } else {
                m.indices.extend([centre, q, p]);
            }
        }
    }
    m
}

/// Every triangle mesh of an imported glTF's default scene, with node
/// transforms baked into the vertices. `path` names it in errors.
fn gltf_mesh(
    path: &str,
    (doc, buffers, _): (
        gltf::Document,
        Vec<gltf::buffer::Data>,
        Vec<gltf::image::Data>,
    ),
) -> Result<Mesh, SceneError> {
    let err = |message: String| SceneError::Gltf {
        path: path.to_owned(),
        message,
    };
    let scene = doc
        .default_scene()
        .or_else(|| doc.scenes().next())
        .ok_or_else(|| err("no scene".into()))?;
    let mut mesh = Mesh::default();
    let mut stack: Vec<(gltf::Node, Mat4)> = scene.nodes().map(|n| (n, Mat4::IDENTITY)).collect();
    while let Some((node, parent)) = stack.pop() {
        let world = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
        let normal_m = Mat3::from_mat4(world).inverse().transpose();
        if let Some(m) = node.mesh() {
            for prim in m.primitives() {
                if prim.mode() != gltf::mesh::Mode::Triangles {
                    continue;
                }
                let reader = prim.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
                let Some(positions) = reader.read_positions() else {
                    continue;
                };
                let positions: Vec<[f32; 3]> = positions.collect();
                let normals: Vec<[f32; 3]> = reader
                    .read_normals()
                    .map(|n| n.collect())
                    .unwrap_or_else(|| vec![[0.0, 1.0, 0.0]; positions.len()]);
                let uvs: Vec<[f32; 2]> = reader
                    .read_tex_coords(0)
                    .map(|t| t.into_f32().collect())
                    .unwrap_or_else(|| vec![[0.0; 2]; positions.len()]);
                let base = mesh.vertices.len() as u32;
                for (i, p) in positions.iter().enumerate() {
                    let n = normals.get(i).copied().unwrap_or([0.0, 1.0, 0.0]);
                    mesh.vertices.push(Vertex {
                        position: world.transform_point3(Vec3::from(*p)).to_array(),
                        normal: (normal_m * Vec3::from(n)).normalize_or(Vec3::Y).to_array(),
                        uv: uvs.get(i).copied().unwrap_or([0.0; 2]),
                    });
                }
                let count = positions.len() as u32;
                match reader.read_indices() {
                    Some(idx) => {
                        for i in idx.into_u32() {
                            if i >= count {
                                return Err(err(format!(
                                    "index {i} out of range ({count} vertices)"
                                )));
                            }
                            mesh.indices.push(base + i);
                        }
                    }
                    None => mesh.indices.extend(base..base + count - count % 3),
                }
            }
        }
        stack.extend(node.children().map(|c| (c, world)));
    }
    if mesh.indices.is_empty() {
        return Err(err("no triangles".into()));
    }
    Ok(mesh)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(m: &Mesh) {
        assert!(!m.indices.is_empty() && m.indices.len() % 3 == 0);
        assert!(m.indices.iter().all(|&i| (i as usize) < m.vertices.len()));
        for v in &m.vertices {
            assert!((Vec3::from(v.normal).length() - 1.0).abs() < 1e-5);
        }
        // Front faces are counter-clockwise seen from outside: the geometric
        // normal agrees with the vertex normals.
        for t in m.indices.chunks(3) {
            let [a, b, c] = [0, 1, 2].map(|k| Vec3::from(m.vertices[t[k] as usize].position));
            let geo = (b - a).cross(c - a);
            // Degenerate triangles at the poles of a sphere have no winding.
            if geo.length() < 1e-6 {
                continue;
            }
            let n: Vec3 = t
                .iter()
                .map(|&i| Vec3::from(m.vertices[i as usize].normal))
                .sum();
            assert!(geo.dot(n) > 0.0, "triangle {t:?} winds inward");
        }
    }

    #[test]
    fn procedural_meshes_are_well_formed() {
        let base = Path::new(".");
        for spec in [
            MeshSpec::Box {
                size: [1.0, 2.0, 3.0],
            },
            MeshSpec::Sphere {
                radius: 0.5,
                segments: 12,
            },
            MeshSpec::Plane { size: [4.0, 2.0] },
            MeshSpec::Cylinder {
                radius: 0.3,
                height: 2.0,
                segments: 8,
            },
            MeshSpec::Rod {
                length: 3.0,
                radius: 0.01,
            },
        ] {
            let m = spec.build(base).unwrap();
            check(&m);
            let (lo, hi) = m.bounds();
            assert!(
                lo.is_finite() && hi.is_finite() && (hi - lo).min_element() >= 0.0,
                "{spec:?}"
            );
        }
        let (lo, hi) = cuboid(Vec3::new(1.0, 2.0, 3.0)).bounds();
        assert_eq!(
            (lo, hi),
            (Vec3::new(-0.5, -1.0, -1.5), Vec3::new(0.5, 1.0, 1.5))
        );
    }

    #[test]
    fn gltf_meshes_load_with_node_transforms() {
        let m = MeshSpec::Gltf {
            path: "builtin:pyramid.gltf".into(),
        }
        .build(Path::new("."))
        .unwrap();
        check(&m);
        assert_eq!(m.indices.len(), 18);
        // The node scales the unit pyramid (apex at 1.2) by 1.5.
        let (lo, hi) = m.bounds();
        assert!(
            (hi.y - 1.8).abs() < 1e-5 && lo.y.abs() < 1e-6 && (hi.x - 0.75).abs() < 1e-5,
            "{lo} {hi}"
        );
        // The same file from disk.
        let dir = std::env::temp_dir().join(format!("gltf-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(
            dir.join("p.gltf"),
            super::super::builtin::asset("pyramid.gltf").unwrap(),
        )
        .unwrap();
        let from_disk = MeshSpec::Gltf {
            path: "p.gltf".into(),
        }
        .build(&dir)
        .unwrap();
        assert_eq!(from_disk, m);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn missing_gltf_is_an_error() {
        let e = MeshSpec::Gltf {
            path: "nope.gltf".into(),
        }
        .build(Path::new("/nonexistent"))
        .unwrap_err();
        assert!(e.to_string().contains("nope.gltf"), "{e}");
    }
}
