//! The splits of a dataset and the seeds they draw their trajectories from.

use serde::{Deserialize, Serialize};

use crate::scenes::TEST_SCENES;
use crate::splitmix64;

/// A split of the dataset.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Split {
    /// Random scenes for training (thesis: 2000).
    Train,
    /// Random scenes from another seed (thesis: 20).
    Valid,
    /// The hand-made scenes of `scenes/test/` (thesis: 10).
    Test,
}

impl Split {
    /// Every split, in the order they are generated.
    pub const ALL: [Split; 3] = [Split::Train, Split::Valid, Split::Test];

    /// The directory name: `train`, `valid` or `test`.
    pub fn name(self) -> &'static str {
        match self {
            Split::Train => "train",
            Split::Valid => "valid",
            Split::Test => "test",
        }
    }

    /// The thesis' number of trajectories.
    pub(crate) fn default_count(self) -> usize {
        match self {
            Split::Train => 2000,
            Split::Valid => 20,
            Split::Test => TEST_SCENES.len(),
        }
    }

    /// The seed of the split's stream of trajectory seeds, from the dataset seed.
    pub fn seed(self, dataset_seed: u64) -> u64 {
        let salt = match self {
            Split::Train => 0x7472_6169_6e00_0000, // "train"
            Split::Valid => 0x7661_6c69_6400_0000, // "valid"
            Split::Test => 0x7465_7374_0000_0000,  // "test"
        };
        splitmix64(dataset_seed ^ salt)
    }
}

impl std::fmt::Display for Split {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Split {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<Self, String> {
        Split::ALL
            .into_iter()
            .find(|split| split.name() == s)
            .ok_or_else(|| format!("unknown split {s:?}; use train, valid or test"))
    }
}
