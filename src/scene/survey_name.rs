//! Survey names. A survey's name is also the name of its folder, `surveys/<name>/`, so it must be
//! a plain name: no separator or `..` that climbs out, nothing a file system folds onto another
//! survey's folder (case, a trailing `.`), nothing a shell reads as an option. One check, used
//! where a name enters a project (`Project::add_survey`) and when `twin.ron` loads.

use std::fmt;

/// Longest survey name, in characters (ASCII, so also bytes). A folder name may be 255 bytes;
/// 64 leaves room for the suffixes of staging and temporary files beside it, and is still four
/// times a name like `2024-06-bridge-north`.
pub const MAX_SURVEY_NAME_CHARS: usize = 64;

/// Why a text is not a survey name.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum BadSurveyName {
    Empty,
    TooLong(usize),
    /// A character outside ASCII letters, digits, `-`, `_` and `.`.
    Character(char),
    /// `.` or `..`: the folder itself or its parent.
    Dots,
    /// Starts with `.`: a hidden folder, and the prefix of the project's own staging files.
    LeadingDot,
    /// Starts with `-`: read as an option by `--survey NAME` and by shells.
    LeadingDash,
    /// Ends with `.`: Windows drops it, so `2024.` would share `2024`'s folder.
    TrailingDot,
    /// A Windows device name (`CON`, `NUL`, `COM1`, …), which no folder there may have.
    Reserved,
}

impl fmt::Display for BadSurveyName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            BadSurveyName::Empty => write!(f, "is empty"),
            BadSurveyName::TooLong(n) => {
                write!(f, "has {n} characters (at most {MAX_SURVEY_NAME_CHARS})")
            }
            BadSurveyName::Character(c) if std::path::is_separator(*c) => write!(
                f,
                "holds the path separator `{c}`: a survey name is a name, not a path"
            ),
            BadSurveyName::Character(c) => write!(
                f,
                "holds `{}`: use ASCII letters, digits, `-`, `_` and `.`",
                c.escape_debug()
            ),
            BadSurveyName::Dots => write!(f, "is a folder, not a name"),
            BadSurveyName::LeadingDot => write!(f, "starts with `.` (a hidden folder)"),
            BadSurveyName::LeadingDash => write!(f, "starts with `-` (it reads as an option)"),
            BadSurveyName::TrailingDot => write!(
                f,
                "ends with `.` (Windows drops it, and the name would share another's folder)"
            ),
            BadSurveyName::Reserved => write!(f, "is a device name on Windows"),
        }
    }
}

/// Checks that `name` can name a survey and its folder (see the module comment).
pub fn check_survey_name(name: &str) -> Result<(), BadSurveyName> {
    if name.is_empty() {
        return Err(BadSurveyName::Empty);
    }
    if let Some(c) = name
        .chars()
        .find(|c| !(c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.')))
    {
        return Err(BadSurveyName::Character(c));
    }
    // ASCII from here on: bytes are characters.
    if name.len() > MAX_SURVEY_NAME_CHARS {
        return Err(BadSurveyName::TooLong(name.len()));
    }
    if name == "." || name == ".." {
        return Err(BadSurveyName::Dots);
    }
    if name.starts_with('.') {
        return Err(BadSurveyName::LeadingDot);
    }
    if name.starts_with('-') {
        return Err(BadSurveyName::LeadingDash);
    }
    if name.ends_with('.') {
        return Err(BadSurveyName::TrailingDot);
    }
    // Windows reserves these with any extension too (`nul.txt`).
    let stem = name.split('.').next().unwrap_or(name).to_ascii_uppercase();
    let numbered = |prefix: &str| {
        stem.strip_prefix(prefix)
            .is_some_and(|d| d.len() == 1 && d.as_bytes()[0].is_ascii_digit() && d != "0")
    };
    if matches!(stem.as_str(), "CON" | "PRN" | "AUX" | "NUL") || numbered("COM") || numbered("LPT")
    {
        return Err(BadSurveyName::Reserved);
    }
    Ok(())
}

/// Whether two survey names would share a folder: compared without case, as macOS and Windows
/// compare folder names.
pub fn same_survey_name(a: &str, b: &str) -> bool {
    a.eq_ignore_ascii_case(b)
}

/// A survey name made from free text (a dataset folder's name, for a survey the app adds):
/// every character a name may not hold becomes `-`, leading `.`/`-` and trailing `.` go, and the
/// result is cut to leave room for a `-N` suffix. `survey` when nothing usable is left.
pub fn survey_name_from(text: &str) -> String {
    let mapped: String = text
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.') {
                c
            } else {
                '-'
            }
        })
        .take(MAX_SURVEY_NAME_CHARS - 8)
        .collect();
    let trimmed = mapped
        .trim_start_matches(['.', '-'])
        .trim_end_matches('.')
        .to_string();
    if check_survey_name(&trimmed).is_ok() {
        trimmed
    } else {
        "survey".to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plain_names_pass() {
        for name in ["2024", "survey-1", "before", "lund_2024.06", "A", "v2.1"] {
            assert_eq!(check_survey_name(name), Ok(()), "{name}");
        }
        assert_eq!(
            check_survey_name(&"a".repeat(MAX_SURVEY_NAME_CHARS)),
            Ok(())
        );
    }

    #[test]
    fn paths_and_aliases_are_refused() {
        use BadSurveyName::*;
        let cases = [
            ("", Empty),
            ("..", Dots),
            (".", Dots),
            ("../../outside", Character('/')),
            ("./2024", Character('/')),
            ("2024/", Character('/')),
            ("x/../2024", Character('/')),
            ("a\\b", Character('\\')),
            ("/etc", Character('/')),
            ("2024 ", Character(' ')),
            ("2024\n", Character('\n')),
            ("brücke", Character('ü')),
            (".hidden", LeadingDot),
            ("-rf", LeadingDash),
            ("2024.", TrailingDot),
            ("nul", Reserved),
            ("Com1.txt", Reserved),
            ("LPT9", Reserved),
        ];
        for (name, why) in cases {
            assert_eq!(check_survey_name(name), Err(why), "{name:?}");
        }
        let long = "a".repeat(MAX_SURVEY_NAME_CHARS + 1);
        assert_eq!(
            check_survey_name(&long),
            Err(TooLong(MAX_SURVEY_NAME_CHARS + 1))
        );
        assert_eq!(check_survey_name("COM0"), Ok(()));
        assert_eq!(check_survey_name("console"), Ok(()));
    }

    #[test]
    fn separators_are_named_as_such() {
        let message = check_survey_name("../x").unwrap_err().to_string();
        assert!(message.contains("path separator"), "{message}");
    }

    #[test]
    fn free_text_becomes_a_valid_name() {
        assert_eq!(survey_name_from("survey-1"), "survey-1");
        assert_eq!(survey_name_from("Brücke 2024"), "Br-cke-2024");
        assert_eq!(survey_name_from(".hidden."), "hidden");
        assert_eq!(survey_name_from(".."), "survey");
        assert_eq!(survey_name_from("nul"), "survey");
        let long = survey_name_from(&"x".repeat(300));
        assert!(check_survey_name(&format!("{long}-999")).is_ok());
        assert!(same_survey_name("Survey", "SURVEY"));
    }
}
