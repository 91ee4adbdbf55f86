//! One entry point for every kind of scene: a built-in name or a TOML file, dispatched on
//! the file's `type` key (`"volume"`, `"soft-tissue"`, or none for cloth). The command
//! line, the dataset generator and the evaluation all load scenes through [`load`], so a
//! scene kind is added in one place.

use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::scenes::cloth::{BUILTIN_SCENES, ClothScene};
use crate::scenes::volume::{BUILTIN_VOLUME_SCENES, SoftTissueScene, VolumeScene};
// The soft-tissue scenes' names live beside `SoftTissueScene`; every built-in is named here.
pub use crate::scenes::volume::{JIGGLE_SCENE, SOFT_TISSUE_SCENE, SOFT_TISSUE_SCENES};

/// A scene of any kind.
#[derive(Debug, Clone, PartialEq)]
pub enum AnyScene {
    Cloth(ClothScene),
    Volume(VolumeScene),
    SoftTissue(SoftTissueScene),
}

/// A loaded scene and the directory its relative file paths (meshes, obstacles) resolve
/// against (`None` for built-ins).
#[derive(Debug, Clone, PartialEq)]
pub struct LoadedScene {
    pub scene: AnyScene,
    pub base_dir: Option<PathBuf>,
}

impl AnyScene {
    pub fn name(&self) -> &str {
        match self {
            Self::Cloth(s) => &s.name,
            Self::Volume(s) => &s.name,
            Self::SoftTissue(s) => &s.name,
        }
    }
    /// Frames the scene simulates.
    pub fn frames(&self) -> usize {
        match self {
            Self::Cloth(s) => s.frames,
            Self::Volume(s) => s.frames,
            Self::SoftTissue(s) => s.frames,
        }
    }
    pub fn set_frames(&mut self, frames: usize) {
        match self {
            Self::Cloth(s) => s.frames = frames,
            Self::Volume(s) => s.frames = frames,
            Self::SoftTissue(s) => s.frames = frames,
        }
    }
    /// The resolved scene as TOML (loadable again by [`load`]).
    pub fn to_toml(&self) -> Result<String> {
        match self {
            Self::Cloth(s) => s.to_toml(),
            Self::Volume(s) => s.to_toml(),
            Self::SoftTissue(s) => s.to_toml(),
        }
    }
    /// Parses TOML text of any scene kind, dispatching on its `type` key.
    pub fn from_toml(text: &str) -> Result<Self> {
        let value: toml::Table = text
            .parse()
            .map_err(|e| Error::Scene(format!("invalid scene TOML: {e}")))?;
        match value.get("type").map(|t| t.as_str()) {
            None => Ok(Self::Cloth(ClothScene::from_toml(text)?)),
            Some(Some("volume")) => Ok(Self::Volume(VolumeScene::from_toml(text)?)),
            Some(Some("soft-tissue")) => Ok(Self::SoftTissue(SoftTissueScene::from_toml(text)?)),
            Some(other) => Err(Error::Scene(format!(
                "unknown scene type {other:?}: use \"volume\", \"soft-tissue\", or no type key for cloth"
            ))),
        }
    }
}

/// Every built-in scene name: cloth, volumetric, then soft tissue.
pub fn builtin_names() -> impl Iterator<Item = &'static str> {
    BUILTIN_SCENES
        .iter()
        .chain(BUILTIN_VOLUME_SCENES.iter())
        .copied()
        .chain(SOFT_TISSUE_SCENES)
}

/// A built-in scene by name (`quick`: its small variant for tests), or else a scene TOML
/// file at that path. Built-in names win over files of the same name.
pub fn load(name_or_path: &str, quick: bool) -> Result<LoadedScene> {
    if let Some(scene) = builtin(name_or_path, quick)? {
        return Ok(LoadedScene { scene, base_dir: None });
    }
    let path = Path::new(name_or_path);
    if !path.is_file() {
        return Err(Error::Scene(format!(
            "{name_or_path:?} is neither a built-in scene ({}) nor a scene file",
            builtin_names().collect::<Vec<_>>().join(", ")
        )));
    }
    if quick {
        // A file has no small variant; simulating it at full size would ignore the request.
        return Err(Error::Scene(format!(
            "{}: the small (quick) variant exists for built-in scenes only; a scene file is simulated as \
             written",
            path.display()
        )));
    }
    let text = std::fs::read_to_string(path).map_err(|e| Error::Scene(format!("reading {}: {e}", path.display())))?;
    let scene = AnyScene::from_toml(&text).map_err(|e| Error::Scene(format!("{}: {e}", path.display())))?;
    Ok(LoadedScene {
        scene,
        base_dir: path.parent().map(Path::to_path_buf),
    })
}

/// The built-in scene of that name, if there is one.
pub fn builtin(name: &str, quick: bool) -> Result<Option<AnyScene>> {
    Ok(if BUILTIN_SCENES.contains(&name) {
        Some(AnyScene::Cloth(ClothScene::builtin(name, quick)?))
    } else if BUILTIN_VOLUME_SCENES.contains(&name) {
        Some(AnyScene::Volume(VolumeScene::builtin(name, quick)?))
    } else if SOFT_TISSUE_SCENES.contains(&name) {
        Some(AnyScene::SoftTissue(SoftTissueScene::builtin_named(name, quick)))
    } else {
        None
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_builtin_loads_and_round_trips_through_toml() {
        for name in builtin_names() {
            let loaded = load(name, true).unwrap();
            assert_eq!(loaded.scene.name(), name);
            let again = AnyScene::from_toml(&loaded.scene.to_toml().unwrap()).unwrap();
            assert_eq!(again, loaded.scene, "{name}");
        }
    }

    #[test]
    fn unknown_names_and_types_are_errors_naming_the_problem() {
        let e = load("no-such-scene", true).unwrap_err().to_string();
        assert!(e.contains("no-such-scene") && e.contains("sheet-ms"), "{e}");
        let e = AnyScene::from_toml("type = \"plasma\"\nname = \"x\"")
            .unwrap_err()
            .to_string();
        assert!(e.contains("plasma"), "{e}");
    }

    #[test]
    fn a_scene_file_loads_as_written_and_refuses_the_quick_variant() {
        let path = std::env::temp_dir().join(format!("weft-sim-load-{}.toml", std::process::id()));
        let scene = load("sheet-ms-17", true).unwrap().scene;
        std::fs::write(&path, scene.to_toml().unwrap()).unwrap();
        let name = path.to_str().unwrap();
        assert_eq!(load(name, false).unwrap().scene, scene);
        let e = load(name, true).unwrap_err().to_string();
        assert!(e.contains("built-in scenes only") && e.contains(name), "{e}");
        std::fs::remove_file(&path).unwrap();
    }
}
