//! COLMAP's own log lines read as progress: the CLI's bar and the app's job progress come from
//! what COLMAP prints, not from a guess of how long it takes. Lines of COLMAP 3.8 and 4.x
//! (glog prefix or none):
//!
//! ```text
//! Processed file [3/29]                 feature extraction
//! Matching image [11/29]                sequential and spatial matching (COLMAP 4: "Processing
//!                                       image [11/29]")
//! Matching block [1/2, 2/2]             exhaustive matching
//! Matching block [1/3]                  a pair list (`matches_importer`)
//! Processing block [1/2, 2/2]           COLMAP 4's exhaustive matching (and "[1/3]": a pair list)
//! Registering image #12 (14)            mapping (COLMAP 4: "(num_reg_frames=14)")
//! ```

/// A step of the pipeline.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    Extract,
    Match,
    Map,
    Write,
}

impl Stage {
    pub fn label(self) -> &'static str {
        match self {
            Stage::Extract => "features",
            Stage::Match => "matching",
            Stage::Map => "mapping",
            Stage::Write => "writing",
        }
    }
}

/// `done` of `total` in `stage`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Progress {
    pub stage: Stage,
    pub done: usize,
    pub total: usize,
}

/// The progress a COLMAP log line reports, if any; `photos` is the number of photos (the
/// mapper's lines count registered images without a total).
pub fn parse_line(line: &str, photos: usize) -> Option<Progress> {
    if let Some(rest) = after(line, "Processed file [") {
        let (done, total) = fraction(rest)?;
        return Some(Progress {
            stage: Stage::Extract,
            done,
            total,
        });
    }
    if let Some(rest) =
        after(line, "Matching image [").or_else(|| after(line, "Processing image ["))
    {
        let (done, total) = fraction(rest)?;
        return Some(Progress {
            stage: Stage::Match,
            done,
            total,
        });
    }
    if let Some(rest) =
        after(line, "Matching block [").or_else(|| after(line, "Processing block ["))
    {
        // "[i/n, j/m]": block (i, j) of n × m, row by row; "[i/n]": block i of a pair list
        // (`matches_importer`).
        let (i, n) = fraction(rest)?;
        let Some((_, second)) = rest
            .split_once(',')
            .filter(|(first, _)| !first.contains(']'))
        else {
            return Some(Progress {
                stage: Stage::Match,
                done: i,
                total: n,
            });
        };
        let (j, m) = fraction(second.trim_start())?;
        return Some(Progress {
            stage: Stage::Match,
            done: (i.checked_sub(1)? * m + j).min(n * m),
            total: n * m,
        });
    }
    if let Some(rest) = after(line, "Registering image #") {
        // "#12 (14)" or "#12 (num_reg_frames=14)": the count registered so far.
        let inside = rest.split_once('(')?.1.split_once(')')?.0;
        let count = inside.rsplit('=').next()?.trim().parse().ok()?;
        return Some(Progress {
            stage: Stage::Map,
            done: usize::min(count, photos),
            total: photos,
        });
    }
    None
}

fn after<'a>(line: &'a str, marker: &str) -> Option<&'a str> {
    line.find(marker).map(|i| &line[i + marker.len()..])
}

/// "3/29]…" or "3/29, …" as (3, 29).
fn fraction(text: &str) -> Option<(usize, usize)> {
    let (done, rest) = text.split_once('/')?;
    let total: String = rest.chars().take_while(|c| c.is_ascii_digit()).collect();
    let (done, total) = (done.trim().parse().ok()?, total.parse().ok()?);
    (total > 0 && done <= total).then_some((done, total))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(stage: Stage, done: usize, total: usize) -> Option<Progress> {
        Some(Progress { stage, done, total })
    }

    #[test]
    fn colmap_log_lines_become_progress() {
        let glog = "I1129 07:46:20.123456  4242 feature_extraction.cc:257] ";
        assert_eq!(
            parse_line(&format!("{glog}Processed file [3/29]"), 29),
            p(Stage::Extract, 3, 29)
        );
        assert_eq!(
            parse_line("Matching image [11/29] in 9.379s", 29),
            p(Stage::Match, 11, 29)
        );
        assert_eq!(
            parse_line("Matching block [2/3, 1/3] in 4.1s", 29),
            p(Stage::Match, 4, 9)
        );
        assert_eq!(
            parse_line("Registering image #12 (14)", 29),
            p(Stage::Map, 14, 29)
        );
        assert_eq!(
            parse_line(
                &format!("{glog}Registering image #5 (num_reg_frames=7)"),
                29
            ),
            p(Stage::Map, 7, 29)
        );
        assert_eq!(
            parse_line("Matching block [2/5] in 1.2s", 29),
            p(Stage::Match, 2, 5)
        );
        assert_eq!(
            parse_line(&format!("{glog}Processing block [1/2, 2/2]"), 29),
            p(Stage::Match, 2, 4)
        );
        assert_eq!(
            parse_line(&format!("{glog}Processing image [4/29]"), 29),
            p(Stage::Match, 4, 29)
        );
        assert_eq!(parse_line("Elapsed time: 0.123 [minutes]", 29), None);
        assert_eq!(parse_line("Processed file [30/29]", 29), None);
        assert_eq!(parse_line("Matching block [0/3, 1/3]", 29), None);
    }
}
