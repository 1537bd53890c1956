//! Which block a job trains when `--block` is not given: the engine says, in its environment.
//! Slurm's array task id first (one task per block), then Slurm's process id (one `srun` step
//! of N tasks), then Kubernetes' Indexed Job completion index.

/// The variables read, in order.
pub const INDEX_VARIABLES: &[&str] = &[
    "SLURM_ARRAY_TASK_ID",
    "SLURM_PROCID",
    "JOB_COMPLETION_INDEX",
];

/// The block index for a plan of `blocks` blocks: `given` when set, else the first of
/// `INDEX_VARIABLES` that `var` finds. An unset index, one that is not a number, or one out of
/// range is an error in one line naming where it came from.
pub fn block_index(
    given: Option<usize>,
    blocks: usize,
    var: impl Fn(&str) -> Option<String>,
) -> Result<usize, String> {
    let (index, source) = match given {
        Some(k) => (k, "--block".to_string()),
        None => {
            let Some((name, text)) = INDEX_VARIABLES
                .iter()
                .find_map(|name| var(name).map(|text| (*name, text)))
            else {
                return Err(format!(
                    "no block given: pass --block K or run under an engine that sets one of {}",
                    INDEX_VARIABLES.join(", ")
                ));
            };
            let k = text
                .trim()
                .parse::<usize>()
                .map_err(|_| format!("{name}={text:?} is not a block index"))?;
            (k, name.to_string())
        }
    };
    if index >= blocks {
        return Err(format!(
            "block {index} (from {source}) is out of range: the plan has blocks 0 to {}",
            blocks.saturating_sub(1)
        ));
    }
    Ok(index)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env<'a>(pairs: &'a [(&'a str, &'a str)]) -> impl Fn(&str) -> Option<String> + 'a {
        move |name| {
            pairs
                .iter()
                .find(|(n, _)| *n == name)
                .map(|(_, v)| v.to_string())
        }
    }

    #[test]
    fn the_flag_wins_then_array_task_then_procid_then_completion_index() {
        let all = [
            ("SLURM_ARRAY_TASK_ID", "1"),
            ("SLURM_PROCID", "2"),
            ("JOB_COMPLETION_INDEX", "3"),
        ];
        assert_eq!(block_index(Some(0), 4, env(&all)), Ok(0));
        assert_eq!(block_index(None, 4, env(&all)), Ok(1));
        assert_eq!(block_index(None, 4, env(&all[1..])), Ok(2));
        assert_eq!(block_index(None, 4, env(&all[2..])), Ok(3));
    }

    #[test]
    fn unset_garbage_and_out_of_range_are_one_line_errors() {
        let none = block_index(None, 4, env(&[])).unwrap_err();
        assert!(
            none.contains("--block") && none.contains("SLURM_ARRAY_TASK_ID"),
            "{none}"
        );
        let bad = block_index(None, 4, env(&[("SLURM_PROCID", "x")])).unwrap_err();
        assert!(bad.contains("SLURM_PROCID"), "{bad}");
        let out = block_index(None, 4, env(&[("JOB_COMPLETION_INDEX", "4")])).unwrap_err();
        assert!(
            out.contains("out of range") && out.contains("JOB_COMPLETION_INDEX"),
            "{out}"
        );
        assert!(
            block_index(Some(9), 4, env(&[]))
                .unwrap_err()
                .contains("--block")
        );
        for e in [none, bad, out] {
            assert!(!e.contains('\n'));
        }
    }
}
