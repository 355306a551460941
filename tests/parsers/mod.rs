//! Property tests of the file parsers a user feeds phi: scene files, optimisation files, the
//! dataset generator's configuration and `metadata.json`. Inputs are the shipped files mutated
//! (numbers swapped for extreme or ill-typed values, bytes cut, inserted, flipped, lines doubled)
//! and arbitrary text. Every input must come back as a value or as an error with a message:
//! no panic, and no input may take long (a hang would fail the time bound).

use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use phi::phi_flip::{OptimizeConfig, RandomSceneParams, Scene};
use phi::phi_gns::data::Metadata;
use proptest::prelude::*;
use proptest::test_runner::{Config, TestCaseError, TestRunner};

/// Inputs per parser: the four together run in a few seconds in a debug build.
const CASES: u32 = 2500;
/// The longest any one input may take to be parsed and checked.
const TIME_BOUND: Duration = Duration::from_secs(5);

/// Values that parsers and checks must refuse or take without harm, written where a number was.
const SUBSTITUTES: &[&str] = &[
    "0",
    "-1",
    "-0.0",
    "1e30",
    "-1e30",
    "1e15",
    "1e400",
    "nan",
    "inf",
    "-inf",
    "NaN",
    "18446744073709551616",
    "4294967296",
    "9007199254740993",
    "1e-45",
    "0.5",
    "1000000000",
    "\"text\"",
    "[]",
    "[1, 2, 3, 4]",
    "true",
    "{}",
];

/// One edit of a text; positions are taken modulo the text's length.
#[derive(Debug, Clone)]
enum Edit {
    /// Replace the `n`-th number with a substitute.
    Number(usize, usize),
    /// Remove up to `len` bytes at a position.
    Cut(usize, usize),
    /// Insert text at a position.
    Insert(usize, String),
    /// XOR one byte with a mask.
    Flip(usize, u8),
    /// Write line `n` twice.
    DoubleLine(usize),
}

fn edit() -> impl Strategy<Value = Edit> {
    prop_oneof![
        4 => (any::<usize>(), 0..SUBSTITUTES.len()).prop_map(|(n, s)| Edit::Number(n, s)),
        1 => (any::<usize>(), 1usize..40).prop_map(|(at, len)| Edit::Cut(at, len)),
        2 => (any::<usize>(), "[ -~\n]{1,16}").prop_map(|(at, s)| Edit::Insert(at, s)),
        1 => (any::<usize>(), 1u8..=255).prop_map(|(at, m)| Edit::Flip(at, m)),
        1 => any::<usize>().prop_map(Edit::DoubleLine),
    ]
}

/// The byte spans of the numbers in `text`.
fn numbers(text: &str) -> Vec<(usize, usize)> {
    let bytes = text.as_bytes();
    let mut spans = Vec::new();
    let mut i = 0;
    while i < bytes.len() {
        let starts = bytes[i].is_ascii_digit()
            || (bytes[i] == b'-' && bytes.get(i + 1).is_some_and(u8::is_ascii_digit));
        let inside_word = i > 0 && (bytes[i - 1].is_ascii_alphanumeric() || bytes[i - 1] == b'_');
        if starts && !inside_word {
            let start = i;
            i += 1;
            while i < bytes.len()
                && matches!(
                    bytes[i],
                    b'0'..=b'9' | b'.' | b'e' | b'E' | b'+' | b'-' | b'_'
                )
            {
                i += 1;
            }
            spans.push((start, i));
        } else {
            i += 1;
        }
    }
    spans
}

fn apply(text: &str, edits: &[Edit]) -> String {
    let mut bytes = text.as_bytes().to_vec();
    for edit in edits {
        let len = bytes.len().max(1);
        match edit {
            Edit::Number(n, s) => {
                let current = String::from_utf8_lossy(&bytes).into_owned();
                let spans = numbers(&current);
                if let Some(&(a, b)) = spans.get(n % spans.len().max(1)) {
                    let mut next = current.as_bytes()[..a].to_vec();
                    next.extend_from_slice(SUBSTITUTES[*s].as_bytes());
                    next.extend_from_slice(&current.as_bytes()[b..]);
                    bytes = next;
                }
            }
            Edit::Cut(at, n) => {
                let start = at % len;
                let end = (start + n).min(bytes.len());
                if start < end {
                    bytes.drain(start..end);
                }
            }
            Edit::Insert(at, s) => {
                let at = at % (bytes.len() + 1);
                bytes.splice(at..at, s.bytes());
            }
            Edit::Flip(at, mask) => {
                if !bytes.is_empty() {
                    let at = at % bytes.len();
                    bytes[at] ^= mask;
                }
            }
            Edit::DoubleLine(n) => {
                let current = String::from_utf8_lossy(&bytes).into_owned();
                let lines: Vec<&str> = current.split_inclusive('\n').collect();
                if !lines.is_empty() {
                    let k = n % lines.len();
                    let mut next = String::new();
                    for (i, line) in lines.iter().enumerate() {
                        next.push_str(line);
                        if i == k {
                            next.push_str(line);
                        }
                    }
                    bytes = next.into_bytes();
                }
            }
        }
    }
    String::from_utf8_lossy(&bytes).into_owned()
}

/// A shipped file mutated, or arbitrary text.
fn input(seeds: Vec<String>) -> impl Strategy<Value = String> {
    let count = seeds.len();
    prop_oneof![
        6 => (0..count, prop::collection::vec(edit(), 1..5))
            .prop_map(move |(i, edits)| apply(&seeds[i], &edits)),
        1 => "(?s).{0,200}",
    ]
}

/// Runs `parse` on [`CASES`] inputs built from `seeds`: each must end in `Ok` or in an error
/// whose message is not empty, within [`TIME_BOUND`]. Returns how many inputs were tried and how
/// many were refused.
fn check_parser(
    name: &str,
    seeds: Vec<String>,
    parse: impl Fn(&str) -> Result<(), String>,
) -> (usize, usize) {
    let mut runner = TestRunner::new(Config {
        cases: CASES,
        failure_persistence: None,
        ..Config::default()
    });
    let (tried, refused) = (AtomicUsize::new(0), AtomicUsize::new(0));
    let result = runner.run(&input(seeds), |text| {
        tried.fetch_add(1, Ordering::Relaxed);
        let started = Instant::now();
        let outcome = parse(&text);
        let took = started.elapsed();
        if took > TIME_BOUND {
            return Err(TestCaseError::fail(format!("{name}: took {took:?}")));
        }
        if let Err(message) = outcome {
            refused.fetch_add(1, Ordering::Relaxed);
            if message.trim().is_empty() {
                return Err(TestCaseError::fail(format!(
                    "{name}: an empty error message"
                )));
            }
        }
        Ok(())
    });
    if let Err(e) = result {
        panic!("{name}: {e}");
    }
    let counts = (tried.into_inner(), refused.into_inner());
    eprintln!(
        "{name}: {} inputs tried, {} refused with an error",
        counts.0, counts.1
    );
    counts
}

fn files(dir: &str) -> Vec<String> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join(dir);
    let mut names: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    names.sort();
    names
        .iter()
        .map(|p| std::fs::read_to_string(p).unwrap())
        .collect()
}

#[test]
fn scene_files_never_panic() {
    let mut seeds = files("scenes");
    seeds.extend(files("scenes/test"));
    let (tried, refused) = check_parser("scene", seeds, |text| {
        Scene::from_toml(text, "fuzz.toml")
            .map(drop)
            .map_err(|e| e.to_string())
    });
    assert_eq!(tried, CASES as usize);
    assert!(
        refused > 0 && refused < tried,
        "{refused} of {tried} refused"
    );
}

#[test]
fn optimisation_files_never_panic() {
    let (tried, refused) = check_parser("optimise", files("scenes/optimize"), |text| {
        OptimizeConfig::from_toml(text, "fuzz.toml")
            .map(drop)
            .map_err(|e| e.to_string())
    });
    assert_eq!(tried, CASES as usize);
    assert!(refused > 0, "{refused} of {tried} refused");
}

#[test]
fn generator_configs_never_panic() {
    let default = toml::to_string(&RandomSceneParams::default()).unwrap();
    // The shipped default must read back as itself.
    assert_eq!(
        RandomSceneParams::from_toml(&default, "default.toml").unwrap(),
        RandomSceneParams::default()
    );
    let (tried, refused) = check_parser("generator config", vec![default], |text| {
        RandomSceneParams::from_toml(text, "gen.toml")
            .map(drop)
            .map_err(|e| e.to_string())
    });
    assert_eq!(tried, CASES as usize);
    assert!(
        refused > 0 && refused < tried,
        "{refused} of {tried} refused"
    );
}

#[test]
fn metadata_files_never_panic() {
    let mut metadata = Metadata::new(2);
    metadata.sequence_length = 400;
    metadata.splits.insert("train".into(), 3);
    metadata.splits.insert("test".into(), 2);
    metadata
        .seeds
        .insert("train".into(), 12_345_678_901_234_567);
    metadata.vel_std = vec![1.2e-3, 0.9e-3];
    metadata.acc_std = vec![1.1e-4, 0.8e-4];
    let seed = serde_json::to_string_pretty(&metadata).unwrap();
    let path = Path::new("metadata.json");
    let parse = |text: &str| -> Result<(), String> {
        let m: Metadata = serde_json::from_str(text).map_err(|e| e.to_string())?;
        m.validate(path).map_err(|e| e.to_string())
    };
    assert_eq!(parse(&seed), Ok(()));
    let (tried, refused) = check_parser("metadata.json", vec![seed], parse);
    assert_eq!(tried, CASES as usize);
    assert!(
        refused > 0 && refused < tried,
        "{refused} of {tried} refused"
    );
}
