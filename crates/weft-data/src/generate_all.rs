//! Generating datasets as a command asks for them: one dataset whose sequences must all
//! complete, every dataset at one size (one failure does not stop the others), the default
//! output directories, and the table of every dataset's size. The generation itself is
//! [`generate`](mod@crate::generate)'s.

use std::path::{Path, PathBuf};

use crate::{DatasetSpec, Error, GenerateOptions, Result, Size, dataset_names};

/// The spec of `name` at `size`, with the sequence and frame counts given over the size's.
pub fn spec_with_counts(
    name: &str,
    size: Size,
    sequences: Option<usize>,
    frames: Option<usize>,
) -> Result<DatasetSpec> {
    let mut spec = DatasetSpec::new(name, size)?;
    if let Some(n) = sequences {
        if n == 0 {
            return Err(Error::Invalid("--sequences must be at least 1".into()));
        }
        spec.sequences = n;
    }
    if let Some(f) = frames {
        if f == 0 {
            return Err(Error::Invalid("--frames must be at least 1".into()));
        }
        spec.frames = f;
    }
    Ok(spec)
}

/// Where a dataset goes without an output directory: `data/<name>-<size>`, or for `all`
/// `data/<size>` with one subdirectory per dataset.
pub fn default_out(name: &str, size: Size) -> PathBuf {
    if name == "all" {
        PathBuf::from(format!("data/{}", size.as_str()))
    } else {
        PathBuf::from(format!("data/{name}-{}", size.as_str()))
    }
}

/// Generates a dataset; sequences that stopped early (stored up to the failure) make it
/// fail after everything else is written.
pub fn generate_complete(spec: &DatasetSpec, out: &Path, options: &GenerateOptions) -> Result<()> {
    let stopped = crate::generate(spec, out, options)?.stopped_early();
    if !stopped.is_empty() {
        return Err(Error::Incomplete(format!(
            "{} sequence(s) stopped early (their frames up to the failure are stored): {}",
            stopped.len(),
            stopped.join("; ")
        )));
    }
    Ok(())
}

/// Generates every dataset into `root/<name>` with `spec_of(name)`; a failing dataset is
/// handed to `failed` and the others go on; fails at the end naming those that failed.
pub fn generate_every(
    root: &Path,
    options: &GenerateOptions,
    spec_of: impl Fn(&str) -> Result<DatasetSpec>,
    mut failed: impl FnMut(&str, Error),
) -> Result<()> {
    let mut names = Vec::new();
    for d in dataset_names() {
        if let Err(e) = generate_complete(&spec_of(d)?, &root.join(d), options) {
            failed(d, e);
            names.push(d);
        }
    }
    if !names.is_empty() {
        return Err(Error::Incomplete(format!(
            "{} dataset(s) failed: {}",
            names.len(),
            names.join(", ")
        )));
    }
    Ok(())
}

/// The table of every dataset's sequences and frames at each size, header first.
pub fn size_table() -> Result<Vec<String>> {
    let mut lines = vec![format!(
        "{:<24} {:>22} {:>22} {:>22}",
        "dataset", "quick", "standard", "paper"
    )];
    for d in dataset_names() {
        let cell = |s| -> Result<String> {
            let spec = DatasetSpec::new(d, s)?;
            Ok(format!("{} × {} frames", spec.sequences, spec.frames))
        };
        lines.push(format!(
            "{d:<24} {:>22} {:>22} {:>22}",
            cell(Size::Quick)?,
            cell(Size::Standard)?,
            cell(Size::Paper)?
        ));
    }
    Ok(lines)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_override_the_size_and_zero_is_refused() {
        let spec = spec_with_counts("limb", Size::Quick, Some(3), None).unwrap();
        assert_eq!(spec.sequences, 3);
        assert_eq!(spec.frames, DatasetSpec::new("limb", Size::Quick).unwrap().frames);
        assert!(spec_with_counts("limb", Size::Quick, None, Some(0)).is_err());
        assert_eq!(default_out("limb", Size::Quick), PathBuf::from("data/limb-quick"));
        assert_eq!(default_out("all", Size::Paper), PathBuf::from("data/paper"));
    }

    #[test]
    fn the_size_table_has_a_row_per_dataset() {
        let table = size_table().unwrap();
        assert_eq!(table.len(), 1 + dataset_names().len());
        assert!(table[0].starts_with("dataset"));
    }
}
