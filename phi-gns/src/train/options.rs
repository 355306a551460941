//! How a front end asks for a run: a new one from a preset and a dataset, or the one in a
//! training directory resumed, with the preset keys it overrides. `phi train` and
//! `phi_rs.train` both resolve their arguments here, so that an option means the same in both.

use std::path::PathBuf;

use super::TrainError;
use super::config::{SelectBy, TrainConfig};
use super::run::{CONFIG_FILE, RunOptions, TrainRecord};

/// The preset keys a front end may override (`phi train --steps`, `phi_rs.train(steps=…)`);
/// `None` keeps the preset's value.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Overrides {
    /// `training.steps`: the total step count.
    pub steps: Option<u64>,
    /// `training.batch_size`.
    pub batch_size: Option<usize>,
    /// `training.seed`: the data and noise draws.
    pub seed: Option<u64>,
    /// `model.noise_std`.
    pub noise_std: Option<f64>,
    /// `training.extra_steps` of the multi-step loss.
    pub extra_steps: Option<usize>,
    /// `training.log_every`.
    pub log_every: Option<u64>,
    /// `checkpoints.every`.
    pub checkpoint_every: Option<u64>,
    /// `screening.every` (0: never).
    pub screen_every: Option<u64>,
    /// `screening.emd_every` (0: no EMD).
    pub emd_every: Option<usize>,
    /// `screening.select_by`.
    pub select_by: Option<SelectBy>,
    /// `training.ema_decay` (switches the weight average on).
    pub ema_decay: Option<f64>,
}

impl Overrides {
    /// Writes the values given into `config` (unchecked: [`TrainConfig::validate`] checks the
    /// result).
    pub fn apply(&self, config: &mut TrainConfig) {
        fn set<T: Copy>(slot: &mut T, value: Option<T>) {
            if let Some(v) = value {
                *slot = v;
            }
        }
        let t = &mut config.training;
        set(&mut t.steps, self.steps);
        set(&mut t.batch_size, self.batch_size);
        set(&mut t.seed, self.seed);
        set(&mut t.extra_steps, self.extra_steps);
        set(&mut t.log_every, self.log_every);
        if self.ema_decay.is_some() {
            t.ema_decay = self.ema_decay;
        }
        set(&mut config.model.noise_std, self.noise_std);
        set(&mut config.checkpoints.every, self.checkpoint_every);
        let s = &mut config.screening;
        set(&mut s.every, self.screen_every);
        set(&mut s.emd_every, self.emd_every);
        set(&mut s.select_by, self.select_by);
    }
}

/// Where a run's configuration and dataset come from.
#[derive(Debug, Clone, PartialEq)]
pub enum RunSource {
    /// A new run: a preset, a dataset and, optionally, the model directory whose weights it
    /// starts from.
    New {
        /// The preset TOML.
        preset: PathBuf,
        /// The dataset directory.
        data: PathBuf,
        /// The model directory of the initial weights (2si starts from a 1s model).
        init_from: Option<PathBuf>,
    },
    /// The run in the training directory continued from its newest checkpoint: its own
    /// `config.toml` and dataset unless others are given.
    Resume {
        /// Another preset (it must describe the same run).
        preset: Option<PathBuf>,
        /// Another path to the run's dataset.
        data: Option<PathBuf>,
    },
}

impl RunOptions {
    /// The options of a run in `out`: the preset of `source` with `overrides` applied and
    /// checked, and the dataset.
    ///
    /// # Errors
    /// [`TrainError::Checkpoint`] for a resumed directory without `train.json`;
    /// [`TrainError::Config`] for a preset that does not read or a value it or the overrides
    /// set that is not allowed (naming the key).
    pub fn resolve(
        out: PathBuf,
        source: RunSource,
        overrides: &Overrides,
    ) -> Result<RunOptions, TrainError> {
        let (preset, data, init_from, resume) = match source {
            RunSource::New {
                preset,
                data,
                init_from,
            } => (preset, data, init_from, false),
            RunSource::Resume { preset, data } => {
                let record = TrainRecord::read(&out)?;
                (
                    preset.unwrap_or_else(|| out.join(CONFIG_FILE)),
                    data.unwrap_or(record.dataset),
                    None,
                    true,
                )
            }
        };
        let mut config = TrainConfig::from_file(&preset)?;
        overrides.apply(&mut config);
        config.validate(&format!("{} (with the overrides)", preset.display()))?;
        Ok(RunOptions {
            out,
            data,
            config,
            preset: preset.display().to_string(),
            init_from,
            resume,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn preset() -> PathBuf {
        PathBuf::from(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../configs/gns/cpu/1s.toml"
        ))
    }

    #[test]
    fn every_override_lands_on_its_key_and_none_keeps_the_preset() {
        let base = TrainConfig::from_file(&preset()).unwrap();
        let mut config = base.clone();
        Overrides::default().apply(&mut config);
        assert_eq!(config, base);
        let overrides = Overrides {
            steps: Some(7),
            batch_size: Some(3),
            seed: Some(9),
            noise_std: Some(1e-3),
            extra_steps: Some(1),
            log_every: Some(5),
            checkpoint_every: Some(10),
            screen_every: Some(20),
            emd_every: Some(4),
            select_by: Some(SelectBy::Emd),
            ema_decay: Some(0.5),
        };
        overrides.apply(&mut config);
        let t = &config.training;
        assert_eq!(
            (t.steps, t.batch_size, t.seed, t.extra_steps, t.log_every),
            (7, 3, 9, 1, 5)
        );
        assert_eq!(t.ema_decay, Some(0.5));
        assert_eq!(config.model.noise_std, 1e-3);
        assert_eq!(config.checkpoints.every, 10);
        let s = &config.screening;
        assert_eq!((s.every, s.emd_every, s.select_by), (20, 4, SelectBy::Emd));
    }

    #[test]
    fn a_new_run_checks_the_overridden_preset_and_a_resume_needs_a_run() {
        let out = std::env::temp_dir().join(format!("phi-options-{}", std::process::id()));
        let new = |overrides: &Overrides| {
            RunOptions::resolve(
                out.clone(),
                RunSource::New {
                    preset: preset(),
                    data: PathBuf::from("data"),
                    init_from: None,
                },
                overrides,
            )
        };
        let options = new(&Overrides::default()).unwrap();
        assert!(!options.resume && options.init_from.is_none());
        assert!(options.preset.ends_with("1s.toml"), "{}", options.preset);
        let e = new(&Overrides {
            select_by: Some(SelectBy::Emd),
            ..Overrides::default()
        })
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("screening.emd_every") && e.contains("overrides"),
            "{e}"
        );
        let e = RunOptions::resolve(
            out.clone(),
            RunSource::Resume {
                preset: None,
                data: None,
            },
            &Overrides::default(),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("train.json"), "{e}");
    }
}
