//! The scenes of a dataset's trajectories: random scenes drawn per thesis table 5.1 (train,
//! valid) and hand-made scene files (test), simulated on the host.

use std::path::Path;

use phi_core::backend::Host;
use phi_flip::{
    ParticleTrajectory, RandomSceneParams, Scene, SceneVariant, cell_centres,
    generate_random_scene, record_trajectory,
};
use phi_geom::{Geometry, Obstacle};

use crate::{DatasetError, Result, Split};

/// `(file name, text)` of `scenes/test/<name>.toml`, compiled in.
macro_rules! test_scene_file {
    ($name:literal) => {
        (
            concat!($name, ".toml"),
            include_str!(concat!(
                env!("CARGO_MANIFEST_DIR"),
                "/../scenes/test/",
                $name,
                ".toml"
            )),
        )
    };
}

/// The test scenes, compiled in: (file name, TOML text).
pub const TEST_SCENES: [(&str, &str); 10] = [
    test_scene_file!("01_tall_drop"),
    test_scene_file!("02_narrow_gap"),
    test_scene_file!("03_stacked_obstacles"),
    test_scene_file!("04_pool_splash"),
    test_scene_file!("05_funnel"),
    test_scene_file!("06_side_jet"),
    test_scene_file!("07_colliding_blocks"),
    test_scene_file!("08_cup"),
    test_scene_file!("09_steep_ramp"),
    test_scene_file!("10_sheet_on_diamond"),
];

/// One simulated trajectory before scaling: positions in cells, liquid first.
#[derive(Debug, Clone)]
pub struct RawTrajectory {
    /// The positions.
    pub trajectory: ParticleTrajectory,
    /// The seed it was made from (random scenes: the drawing seed; test scenes: the scene's).
    pub seed: u64,
}

/// The scenes of a test split: the ten built-in ones of `scenes/test/`, or the scene files of a
/// folder (`phi dataset generate --scenes DIR`), in file-name order.
#[derive(Debug, Clone, PartialEq)]
pub struct TestScenes {
    /// Where the scenes come from in messages: `scenes/test` or the folder given.
    pub origin: String,
    /// `(file name, TOML text)` per scene.
    pub files: Vec<(String, String)>,
    /// Whether these are the built-in scenes.
    pub builtin: bool,
}

impl Default for TestScenes {
    fn default() -> Self {
        Self::builtin()
    }
}

impl TestScenes {
    /// The ten scenes of `scenes/test/`, compiled in.
    pub fn builtin() -> Self {
        Self {
            origin: "scenes/test".into(),
            files: TEST_SCENES
                .iter()
                .map(|(name, text)| (name.to_string(), text.to_string()))
                .collect(),
            builtin: true,
        }
    }

    /// The `*.toml` files of `dir`, sorted by name, each parsed and checked for a dataset
    /// ([`TestScenes::scene`]); they must share one domain size and time step.
    ///
    /// # Errors
    /// A folder that cannot be read or holds no scene file, an invalid scene (naming the file),
    /// scenes of different domain sizes or time steps.
    pub fn from_dir(dir: &Path) -> Result<Self> {
        let mut names = Vec::new();
        let entries = std::fs::read_dir(dir).map_err(|e| DatasetError::io(dir, "reading", e))?;
        for entry in entries {
            let path = entry
                .map_err(|e| DatasetError::io(dir, "listing", e))?
                .path();
            if path.extension().is_some_and(|e| e == "toml") && path.is_file() {
                names.push(path);
            }
        }
        names.sort();
        if names.is_empty() {
            return Err(DatasetError::Directory {
                path: dir.to_path_buf(),
                reason: "holds no scene files (*.toml)".into(),
            });
        }
        let mut files = Vec::new();
        for path in names {
            let text = std::fs::read_to_string(&path)
                .map_err(|e| DatasetError::io(&path, "reading", e))?;
            let name =
                path.file_name()
                    .and_then(|n| n.to_str())
                    .ok_or_else(|| DatasetError::Invalid {
                        path: path.display().to_string(),
                        reason: "the file name is not UTF-8".into(),
                    })?;
            files.push((name.to_string(), text));
        }
        let scenes = Self {
            origin: dir.display().to_string(),
            files,
            builtin: false,
        };
        let first = scenes.scene(0, SceneVariant::Obstacles)?;
        for index in 1..scenes.len() {
            let scene = scenes.scene(index, SceneVariant::Obstacles)?;
            for (key, a, b) in [
                (
                    "domain.resolution",
                    format!("{:?}", first.domain.resolution),
                    format!("{:?}", scene.domain.resolution),
                ),
                (
                    "simulation.dt",
                    first.simulation.dt.to_string(),
                    scene.simulation.dt.to_string(),
                ),
            ] {
                if a != b {
                    return Err(DatasetError::Invalid {
                        path: scenes.path(index),
                        reason: format!(
                            "{key} is {b}, but {} has {a}; the scenes of one dataset share \
                             their domain size and time step",
                            scenes.path(0)
                        ),
                    });
                }
            }
        }
        Ok(scenes)
    }

    /// How many scenes there are.
    pub fn len(&self) -> usize {
        self.files.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.files.is_empty()
    }

    /// The file names.
    pub fn names(&self) -> Vec<String> {
        self.files.iter().map(|(n, _)| n.clone()).collect()
    }

    /// `origin/name` of scene `index`.
    pub fn path(&self, index: usize) -> String {
        format!("{}/{}", self.origin, self.files[index].0)
    }

    /// The domain size and time step the scenes share (the first scene's).
    ///
    /// # Errors
    /// An invalid first scene.
    pub fn domain(&self) -> Result<([usize; 2], f32)> {
        let scene = self.scene(0, SceneVariant::Obstacles)?;
        let r = &scene.domain.resolution;
        Ok(([r[0], r[1]], scene.simulation.dt))
    }

    /// The CRC-32 of every name and text, which decides the files of a folder's scenes.
    pub fn crc32(&self) -> u32 {
        let mut hasher = crc32fast::Hasher::new();
        for (name, text) in &self.files {
            for part in [name.as_bytes(), b"\0", text.as_bytes(), b"\0"] {
                hasher.update(part);
            }
        }
        hasher.finalize()
    }

    /// Scene `index`, checked for the dataset (2D, no inflows), with the wall ring added in the
    /// `walls` variant.
    ///
    /// # Errors
    /// An index past the scenes, an invalid scene file (naming it).
    pub fn scene(&self, index: usize, variant: SceneVariant) -> Result<Scene> {
        let Some((_, text)) = self.files.get(index) else {
            return Err(DatasetError::Invalid {
                path: self.origin.clone(),
                reason: format!("holds {} test scenes, not {}", self.len(), index + 1),
            });
        };
        let origin = self.path(index);
        let mut scene = Scene::from_toml(text, &origin)?;
        if scene.dim() != 2 || !scene.inflows.is_empty() {
            return Err(DatasetError::Invalid {
                path: origin,
                reason: "a dataset scene is 2-dimensional and has no inflows".into(),
            });
        }
        if variant == SceneVariant::Walls {
            let [nx, ny] =
                [scene.domain.resolution[0], scene.domain.resolution[1]].map(|n| n as f32);
            for (lower, upper) in [
                ([0.0, 0.0], [1.0, ny]),
                ([nx - 1.0, 0.0], [nx, ny]),
                ([1.0, 0.0], [nx - 1.0, 1.0]),
                ([1.0, ny - 1.0], [nx - 1.0, ny]),
            ] {
                scene
                    .obstacles
                    .push(Obstacle::at_rest(Geometry::boxed(lower, upper)?)?);
            }
        }
        Ok(scene)
    }
}

/// Simulates trajectory `index` of `split`: a random scene drawn from `seed` (train, valid) or
/// scene `index` of `scenes` (test); `steps` overrides the step count of test scenes. Runs on
/// the calling thread ([`Host`], the ndarray backend; the 32×32 kernels stay below its parallel
/// threshold).
///
/// # Errors
/// A scene that cannot be drawn or built, a failing simulation step.
pub fn simulate_trajectory(
    split: Split,
    index: usize,
    seed: u64,
    params: &RandomSceneParams,
    variant: SceneVariant,
    scenes: &TestScenes,
    steps: usize,
) -> Result<RawTrajectory> {
    match split {
        Split::Train | Split::Valid => {
            let scene = generate_random_scene(params, variant, seed)?;
            let (simulation, particles) = scene.simulation(params.dt)?;
            let trajectory =
                record_trajectory(&simulation, particles, &scene.obstacle_particles, steps)?;
            Ok(RawTrajectory { trajectory, seed })
        }
        Split::Test => {
            let scene = scenes.scene(index, variant)?;
            let setup = scene.build::<Host>(&scenes.path(index), &Default::default())?;
            let ny = scene.domain.resolution[1];
            let obstacle_particles = cell_centres(&setup.simulation.solid_cells(0.0)?, ny);
            let trajectory = record_trajectory(
                &setup.simulation,
                setup.particles,
                &obstacle_particles,
                steps,
            )?;
            Ok(RawTrajectory {
                trajectory,
                seed: scene.simulation.seed,
            })
        }
    }
}

/// The position scale and offset of the stored positions: the grid of unit cells maps onto
/// `[0.1, 0.9]` along its longest axis, as in the thesis (`x / 40 + 0.1` at 32 cells), unless
/// `scale` (`--position-scale`) sets the stored units per cell.
pub fn position_scale(resolution: [usize; 2], scale: Option<f64>) -> (f32, f32) {
    match scale {
        Some(scale) => (scale as f32, 0.1),
        None => (0.8 / resolution[0].max(resolution[1]) as f32, 0.1),
    }
}
