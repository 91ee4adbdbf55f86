//! Meshes for weft: validated triangle and tetrahedral meshes, their topology and
//! geometry, the built-in generators every scene uses, and file I/O.
//!
//! This is the lowest layer of the workspace. It knows nothing of physics: there are no
//! energies, solvers or materials here, only the connectivity and geometric quantities
//! (areas, cotangent weights, dihedral angles, rest-shape matrices, lumped masses) that
//! the simulator, ACAP features and projection layers build on. It is also the only
//! library crate that reads or writes mesh files.
//!
//! Invariant: a [`TriMesh`] or [`TetMesh`] that exists is valid — finite coordinates,
//! indices in range, no repeated index in an element, edge-manifold and consistently
//! oriented surfaces, positively oriented tetrahedra. Bad input is a typed [`Error`]
//! naming the offending element, never a panic.
//!
//! Units: metres, kilograms, radians.
//!
//! ```
//! use weft_mesh::{generators, Topology};
//! let sheet = generators::sheet(17, 1.0)?;
//! assert_eq!(sheet.num_vertices(), 289);
//! let topo = Topology::new(&sheet);
//! assert_eq!(topo.boundary_loops.len(), 1);
//! assert!((sheet.area() - 1.0).abs() < 1e-12);
//! # Ok::<(), weft_mesh::Error>(())
//! ```

mod element;
pub mod error;
pub mod generators;
pub mod geodesic;
pub mod geometry;
pub mod info;
pub mod io;
pub mod limb;
pub mod tetmesh;
pub mod topology;
pub mod trimesh;

pub use error::{Error, Result};
pub use tetmesh::{BoundarySurface, TetMesh};
pub use topology::{Adjacency, Hinge, TetTopology, Topology};
pub use trimesh::{TriMesh, flatten, unflatten};
