//! The shape every experiment's hyper-parameter studies share: candidates swept, each
//! trained and scored by the experiment, the one to keep chosen on the validation split
//! alone, and the table rows that record the sweep with the choice marked.
//!
//! A [`Study`] holds the trials (candidate, outcome) in the order they were swept and the
//! index of the chosen one. The choice sees an outcome only through the `validation`
//! function the caller passes (or a rule over the trials, [`Study::choose_with`]), so what
//! an outcome carries from the test split can never move it. Lower validation scores are
//! better; ties go to the first candidate swept (the configuration's own comes first by
//! convention), and a NaN score loses to any number.
//!
//! Not here: training, scoring, where models live, tables' titles and captions — each
//! experiment keeps those. A sweep that trains its candidates concurrently builds the
//! trials itself and hands them to [`Study::from_trials`].

use std::cmp::Ordering;

/// A swept study: every candidate with its outcome, in sweep order, and the choice.
#[derive(Debug, Clone)]
pub(crate) struct Study<C, O> {
    trials: Vec<(C, O)>,
    chosen: usize,
}

impl<C, O> Study<C, O> {
    /// Runs `run` on every candidate in order (stopping at the first error) and chooses
    /// the outcome whose `validation` score is lowest ([`choose_on_validation`]).
    pub(crate) fn sweep(
        candidates: impl IntoIterator<Item = C>,
        mut run: impl FnMut(&C) -> crate::Result<O>,
        validation: impl Fn(&O) -> f64,
    ) -> crate::Result<Self> {
        let mut trials = Vec::new();
        for candidate in candidates {
            let outcome = run(&candidate)?;
            trials.push((candidate, outcome));
        }
        Self::from_trials(trials, validation)
    }

    /// The study of trials already run (for example concurrently), chosen by the lowest
    /// `validation` score ([`choose_on_validation`]). An error if there is no trial.
    pub(crate) fn from_trials(trials: Vec<(C, O)>, validation: impl Fn(&O) -> f64) -> crate::Result<Self> {
        let chosen = choose_on_validation(trials.iter().map(|(_, o)| validation(o)));
        Self::with_choice(trials, chosen)
    }

    /// The study of `trials` chosen by `rule` (the chosen trial's index), for a choice that
    /// is more than the lowest score (embed's λ_ephys: the lowest M_phys among the
    /// candidates close enough to a baseline's M_rms). `rule` must read validation scores
    /// only. An error if it chooses nothing or an index out of range.
    pub(crate) fn choose_with(
        trials: Vec<(C, O)>,
        rule: impl FnOnce(&[(C, O)]) -> Option<usize>,
    ) -> crate::Result<Self> {
        let chosen = rule(&trials);
        Self::with_choice(trials, chosen)
    }

    fn with_choice(trials: Vec<(C, O)>, chosen: Option<usize>) -> crate::Result<Self> {
        match chosen {
            Some(chosen) if chosen < trials.len() => Ok(Self { trials, chosen }),
            _ => Err(crate::Error::Invalid(format!(
                "a study of {} candidate(s) chose none",
                trials.len()
            ))),
        }
    }

    /// Every (candidate, outcome), in sweep order.
    pub(crate) fn trials(&self) -> &[(C, O)] {
        &self.trials
    }

    /// The chosen trial's index in [`Study::trials`] (the experiments take it with the
    /// trials, [`Study::into_parts`]).
    #[cfg(test)]
    pub(crate) fn chosen_index(&self) -> usize {
        self.chosen
    }

    /// The chosen candidate.
    pub(crate) fn chosen(&self) -> &C {
        &self.trials[self.chosen].0
    }

    /// The chosen candidate's outcome.
    pub(crate) fn chosen_outcome(&self) -> &O {
        &self.trials[self.chosen].1
    }

    /// The trials, and the chosen one's index, to take the outcomes apart.
    pub(crate) fn into_parts(self) -> (Vec<(C, O)>, usize) {
        (self.trials, self.chosen)
    }

    /// A table row per trial, `row`'s cells followed by a last cell `"chosen"` on the
    /// chosen trial and `""` on the others.
    pub(crate) fn rows(&self, row: impl Fn(&C, &O) -> Vec<String>) -> Vec<Vec<String>> {
        self.trials
            .iter()
            .enumerate()
            .map(|(i, (c, o))| {
                let mut cells = row(c, o);
                cells.push(if i == self.chosen { "chosen" } else { "" }.into());
                cells
            })
            .collect()
    }
}

/// The index of the lowest validation score: ties go to the first, a NaN loses to any
/// number (a diverged run is never kept over one that trained); `None` without scores.
pub(crate) fn choose_on_validation(scores: impl IntoIterator<Item = f64>) -> Option<usize> {
    scores
        .into_iter()
        .enumerate()
        .min_by(|a, b| compare_scores(a.1, b.1))
        .map(|(i, _)| i)
}

/// Lower is better, NaN after every number; `Iterator::min_by` keeps the first of equals.
fn compare_scores(a: f64, b: f64) -> Ordering {
    match (a.is_nan(), b.is_nan()) {
        (false, false) => a.total_cmp(&b),
        (a_nan, b_nan) => a_nan.cmp(&b_nan),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What a candidate's closure returns in the tests: a validation score and a test
    /// score the choice must never read.
    #[derive(Debug, Clone, Copy)]
    struct Scored {
        validation: f64,
        test: f64,
    }

    #[test]
    fn the_lowest_validation_score_is_chosen_and_ties_go_to_the_first() {
        assert_eq!(choose_on_validation([3.0, 1.0, 2.0]), Some(1));
        assert_eq!(choose_on_validation([2.0, 1.0, 1.0, 5.0]), Some(1));
        assert_eq!(choose_on_validation([0.0, -0.0]), Some(1), "total order: -0 < +0");
        assert_eq!(choose_on_validation([]), None);
    }

    #[test]
    fn a_nan_score_is_never_chosen_over_a_number() {
        // x86's default NaN has its sign bit set, which `total_cmp` alone orders first.
        let negative_nan = f64::from_bits(f64::NAN.to_bits() | (1 << 63));
        assert_eq!(choose_on_validation([negative_nan, 2.0, f64::NAN, 1.0]), Some(3));
        assert_eq!(choose_on_validation([f64::NAN, f64::INFINITY]), Some(1));
        assert_eq!(choose_on_validation([f64::NAN, f64::NAN]), Some(0));
    }

    #[test]
    fn a_poisoned_test_split_never_moves_the_choice() {
        let candidates = [0.1f64, 0.01, 0.001];
        let sweep = |poison: bool| {
            Study::sweep(
                candidates,
                |&rate| {
                    Ok(Scored {
                        validation: (rate.log10() + 2.0).abs(),
                        // The best test score on another candidate, or NaN everywhere.
                        test: if poison {
                            if rate == 0.1 { -1e9 } else { f64::NAN }
                        } else {
                            rate
                        },
                    })
                },
                |s| s.validation,
            )
            .unwrap()
        };
        let (clean, poisoned) = (sweep(false), sweep(true));
        assert_eq!(*clean.chosen(), 0.01);
        assert_eq!(clean.chosen_index(), poisoned.chosen_index());
        assert!(poisoned.chosen_outcome().test.is_nan());
    }

    #[test]
    fn a_sweep_runs_every_candidate_in_order_and_stops_at_an_error() {
        let mut seen = Vec::new();
        let study = Study::sweep(
            ["a", "b", "c"],
            |&c| {
                seen.push(c);
                Ok(c.len() as f64)
            },
            |&v| v,
        )
        .unwrap();
        assert_eq!(seen, ["a", "b", "c"]);
        assert_eq!(*study.chosen(), "a");
        let failed = Study::sweep(
            [1, 2, 3],
            |&c| {
                if c == 2 {
                    Err(crate::Error::Failed("diverged".into()))
                } else {
                    Ok(c as f64)
                }
            },
            |&v| v,
        );
        assert!(matches!(failed, Err(crate::Error::Failed(_))));
    }

    #[test]
    fn trials_run_elsewhere_are_chosen_alike() {
        let trials = vec![("x", 2.0), ("y", 1.0)];
        let study = Study::from_trials(trials, |&v| v).unwrap();
        assert_eq!((*study.chosen(), *study.chosen_outcome()), ("y", 1.0));
        let (trials, chosen) = study.into_parts();
        assert_eq!((trials.len(), chosen), (2, 1));
    }

    #[test]
    fn a_study_without_a_choice_is_an_error() {
        assert!(Study::<u8, f64>::from_trials(Vec::new(), |&v| v).is_err());
        assert!(Study::choose_with(vec![(1, 1.0)], |_| None).is_err());
        assert!(Study::choose_with(vec![(1, 1.0)], |_| Some(1)).is_err());
        let rule = Study::choose_with(vec![(1, 3.0), (2, 1.0)], |t| t.iter().position(|(_, v)| *v > 2.0)).unwrap();
        assert_eq!(*rule.chosen(), 1);
    }

    #[test]
    fn rows_end_with_the_choice_marked() {
        let study = Study::from_trials(vec![("constant", 2.0), ("halve", 1.0)], |&v| v).unwrap();
        let rows = study.rows(|c, v| vec![c.to_string(), format!("{v:.1}")]);
        assert_eq!(rows, [["constant", "2.0", ""], ["halve", "1.0", "chosen"]]);
    }
}
