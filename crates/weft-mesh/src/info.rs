//! What a mesh file holds, as `cargo xtask mesh info` prints it: counts, topology and
//! geometry of a surface or a volume, and whether the file reads as a valid mesh at all.
//! It reports; it does not repair or change a mesh.

use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::io::{self, AnyMesh};
use crate::{Result, TetMesh, TetTopology, Topology, TriMesh};

/// A triangle surface's counts and measures.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SurfaceInfo {
    pub kind: &'static str,
    pub vertices: usize,
    pub faces: usize,
    pub edges: usize,
    pub boundary_loops: usize,
    pub euler_characteristic: i64,
    pub area_m2: f64,
    pub bounding_box_diagonal_m: f64,
    /// The first face of zero area, if any.
    pub degenerate_faces: Option<String>,
}

/// A tetrahedral volume's counts and measures (its boundary's too).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct VolumeInfo {
    pub kind: &'static str,
    pub vertices: usize,
    pub tetrahedra: usize,
    pub edges: usize,
    pub boundary_faces: usize,
    pub boundary_vertices: usize,
    pub boundary_loops: usize,
    pub volume_m3: f64,
}

/// A mesh's counts and measures, by its kind.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(untagged)]
pub enum MeshInfo {
    Surface(SurfaceInfo),
    Volume(VolumeInfo),
}

impl SurfaceInfo {
    pub fn of(m: &TriMesh) -> Self {
        let t = Topology::new(m);
        Self {
            kind: "triangle surface",
            vertices: m.num_vertices(),
            faces: m.num_faces(),
            edges: t.edges.len(),
            boundary_loops: t.boundary_loops.len(),
            euler_characteristic: m.euler_characteristic(),
            area_m2: m.area(),
            bounding_box_diagonal_m: m.bounding_box_diagonal(),
            degenerate_faces: m.check_face_areas(0.0).err().map(|e| e.to_string()),
        }
    }
}

impl VolumeInfo {
    /// Fails if the volume's boundary is not a valid surface.
    pub fn of(m: &TetMesh) -> Result<Self> {
        let s = m.boundary_surface()?;
        Ok(Self {
            kind: "tetrahedral volume",
            vertices: m.num_vertices(),
            tetrahedra: m.num_tets(),
            edges: TetTopology::new(m).edges.len(),
            boundary_faces: s.mesh.num_faces(),
            boundary_vertices: s.mesh.num_vertices(),
            boundary_loops: Topology::new(&s.mesh).boundary_loops.len(),
            volume_m3: m.volume(),
        })
    }
}

impl MeshInfo {
    pub fn of(mesh: &AnyMesh) -> Result<Self> {
        Ok(match mesh {
            AnyMesh::Surface(m) => Self::Surface(SurfaceInfo::of(m)),
            AnyMesh::Volume(m) => Self::Volume(VolumeInfo::of(m)?),
        })
    }
}

impl AnyMesh {
    /// Writes the mesh, the format following the extension (see [`io::write_surface`] and
    /// [`io::write_volume`]).
    pub fn write(&self, path: &Path) -> Result<()> {
        match self {
            AnyMesh::Surface(m) => io::write_surface(path, m),
            AnyMesh::Volume(m) => io::write_volume(path, m),
        }
    }

    /// Its size in words: `N vertices, M faces` or `N vertices, M tetrahedra`.
    pub fn counts(&self) -> String {
        match self {
            AnyMesh::Surface(m) => format!("{} vertices, {} faces", m.num_vertices(), m.num_faces()),
            AnyMesh::Volume(m) => format!("{} vertices, {} tetrahedra", m.num_vertices(), m.num_tets()),
        }
    }
}

/// A mesh file's report: valid with its [`MeshInfo`], or invalid with the reader's error.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MeshFileReport {
    pub file: PathBuf,
    pub valid: bool,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    #[serde(flatten)]
    pub info: Option<MeshInfo>,
}

impl MeshFileReport {
    /// Reads `file`; a file that does not read as a mesh is reported invalid, not an error.
    /// Fails only if a volume read has an invalid boundary.
    pub fn read(file: &Path) -> Result<Self> {
        let (error, info) = match io::read_mesh(file) {
            Err(e) => (Some(e.to_string()), None),
            Ok(mesh) => (None, Some(MeshInfo::of(&mesh)?)),
        };
        Ok(Self {
            file: file.to_path_buf(),
            valid: error.is_none(),
            error,
            info,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::generators;

    #[test]
    fn surfaces_and_volumes_report_their_counts() {
        let sheet = SurfaceInfo::of(&generators::sheet(3, 1.0).unwrap());
        assert_eq!((sheet.vertices, sheet.faces, sheet.boundary_loops), (9, 8, 1));
        assert_eq!(sheet.euler_characteristic, 1);
        assert!((sheet.area_m2 - 1.0).abs() < 1e-12 && sheet.degenerate_faces.is_none());
        let beam = generators::beam(&generators::BeamParams {
            cells: [2, 1, 1],
            size: [2.0, 1.0, 1.0],
        })
        .unwrap();
        let MeshInfo::Volume(v) = MeshInfo::of(&AnyMesh::Volume(beam)).unwrap() else {
            panic!("a beam is a volume")
        };
        assert_eq!((v.vertices, v.tetrahedra, v.boundary_loops), (12, 12, 0));
        let sheet = AnyMesh::Surface(generators::sheet(3, 1.0).unwrap());
        assert_eq!(sheet.counts(), "9 vertices, 8 faces");
        assert!((v.volume_m3 - 2.0).abs() < 1e-12);
    }

    #[test]
    fn a_missing_file_is_reported_invalid() {
        let r = MeshFileReport::read(Path::new("/nonexistent/weft-mesh-info.obj")).unwrap();
        assert!(!r.valid && r.error.is_some() && r.info.is_none());
    }
}
