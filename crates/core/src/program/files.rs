//! A table version's program files kept as one text: programs in the transfer format one
//! after another, each from its `%_N_<NAME>_SPF` line (the form a SINUMERIK archive of
//! several programs takes). With the speed plan in the whole cycle a version is two table
//! programs (X over C, and C and X over the virtual axis), pushed and kept together so that
//! neither is ever delivered without the other.

use thiserror::Error;

/// One program of a version's text.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ProgramText<'t> {
    /// The file's name on the share, `<NAME>.SPF` (or `.MPF`).
    pub file: String,
    /// Its text, from its `%_N_` line to the line before the next program's.
    pub text: &'t str,
}

#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum ProgramFilesError {
    #[error("line {line}: text before the first program's `%_N_<NAME>_SPF` line")]
    BeforeFirst { line: usize },
    #[error("line {line}: `{header}` names no program (`%_N_<NAME>_SPF` or `_MPF`)")]
    BadHeader { line: usize, header: String },
    #[error("no program in the text")]
    Empty,
    #[error("the programs are {}, not {}", .found.join(", "), .expected.join(" then "))]
    NotExpected {
        found: Vec<String>,
        expected: Vec<String>,
    },
}

/// The programs of `text`, in order.
pub fn split_program_files(text: &str) -> Result<Vec<ProgramText<'_>>, ProgramFilesError> {
    let mut out: Vec<(String, usize)> = Vec::new();
    let mut offset = 0;
    for (i, line) in text.split_inclusive('\n').enumerate() {
        let trimmed = line.trim_end();
        if let Some(rest) = trimmed.strip_prefix("%_N_") {
            let file = rest
                .strip_suffix("_SPF")
                .map(|n| format!("{n}.SPF"))
                .or_else(|| rest.strip_suffix("_MPF").map(|n| format!("{n}.MPF")))
                .filter(|f| f.len() > 4)
                .ok_or_else(|| ProgramFilesError::BadHeader {
                    line: i + 1,
                    header: trimmed.to_string(),
                })?;
            out.push((file, offset));
        } else if out.is_empty() && !trimmed.is_empty() {
            return Err(ProgramFilesError::BeforeFirst { line: i + 1 });
        }
        offset += line.len();
    }
    if out.is_empty() {
        return Err(ProgramFilesError::Empty);
    }
    let ends: Vec<usize> = out
        .iter()
        .skip(1)
        .map(|(_, start)| *start)
        .chain([text.len()])
        .collect();
    Ok(out
        .into_iter()
        .zip(ends)
        .map(|((file, start), end)| ProgramText {
            file,
            text: &text[start..end],
        })
        .collect())
}

/// The programs of `text`, which must be the files `expected` in that order (program names
/// are case-insensitive on the control): each named as `expected` names it.
pub fn expected_program_files<'t>(
    text: &'t str,
    expected: &[&str],
) -> Result<Vec<ProgramText<'t>>, ProgramFilesError> {
    let files = split_program_files(text)?;
    let same = files.len() == expected.len()
        && files
            .iter()
            .zip(expected)
            .all(|(f, e)| f.file.eq_ignore_ascii_case(e));
    if !same {
        return Err(ProgramFilesError::NotExpected {
            found: files.into_iter().map(|f| f.file).collect(),
            expected: expected.iter().map(|e| e.to_string()).collect(),
        });
    }
    Ok(files
        .into_iter()
        .zip(expected)
        .map(|(f, e)| ProgramText {
            file: e.to_string(),
            text: f.text,
        })
        .collect())
}

/// Each `CTABDEF … CTABEND` of a table program as a program of its own (its `PROC` line
/// first), so a two-table program reads back table by table.
pub fn table_definitions(text: &str) -> Vec<String> {
    let proc_line = text
        .lines()
        .find(|l| l.trim_start().starts_with("PROC "))
        .unwrap_or_default();
    let mut out = Vec::new();
    let mut current: Option<String> = None;
    for line in text.lines() {
        let t = line.trim_start();
        if t.starts_with("CTABDEF(") {
            current = Some(format!("{proc_line}\n"));
        }
        if let Some(c) = current.as_mut() {
            c.push_str(line);
            c.push('\n');
        }
        if t.starts_with("CTABEND") {
            out.extend(current.take());
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_programs_split_at_their_headers_and_join_back() {
        let text = "%_N_CAM_SPF\n;$PATH=/_N_SPF_DIR\nPROC CAM\nRET\n%_N_CAM_V_SPF\n;$PATH=/_N_SPF_DIR\nPROC CAM_V\nRET\n";
        let files = split_program_files(text).unwrap();
        let names: Vec<&str> = files.iter().map(|f| f.file.as_str()).collect();
        assert_eq!(names, ["CAM.SPF", "CAM_V.SPF"]);
        assert!(files[0].text.ends_with("PROC CAM\nRET\n"));
        assert!(files[1].text.starts_with("%_N_CAM_V_SPF\n"));
        let joined: String = files.iter().map(|f| f.text).collect();
        assert_eq!(joined, text);
    }

    #[test]
    fn text_outside_a_program_is_refused_naming_its_line() {
        assert_eq!(
            split_program_files("\nCTABEND\n%_N_A_SPF\n"),
            Err(ProgramFilesError::BeforeFirst { line: 2 })
        );
        assert_eq!(
            split_program_files("%_N__SPF\n"),
            Err(ProgramFilesError::BadHeader {
                line: 1,
                header: "%_N__SPF".into()
            })
        );
        assert_eq!(split_program_files(""), Err(ProgramFilesError::Empty));
    }

    #[test]
    fn only_the_files_expected_in_their_order_are_taken() {
        let text = "%_N_cam_SPF\nPROC CAM\n%_N_CAM_P_SPF\nPROC CAM_P\n";
        let files = expected_program_files(text, &["CAM.SPF", "CAM_P.SPF"]).unwrap();
        assert_eq!(files[0].file, "CAM.SPF", "named as expected, case aside");
        assert_eq!(files[1].text, "%_N_CAM_P_SPF\nPROC CAM_P\n");
        for expected in [
            &["CAM_P.SPF", "CAM.SPF"][..],
            &["CAM.SPF"][..],
            &["CAM.SPF", "CAM_P.SPF", "MAIN.MPF"][..],
        ] {
            let e = expected_program_files(text, expected).unwrap_err();
            assert!(
                matches!(&e, ProgramFilesError::NotExpected { found, .. } if found == &["cam.SPF", "CAM_P.SPF"]),
                "{e}"
            );
        }
        assert_eq!(
            expected_program_files("%_N_CAM_SPF\n", &["CAM.SPF", "CAM_P.SPF"])
                .unwrap_err()
                .to_string(),
            "the programs are CAM.SPF, not CAM.SPF then CAM_P.SPF"
        );
    }

    #[test]
    fn each_table_of_a_two_table_program_stands_alone() {
        let text = "%_N_P_SPF\nPROC P(VAR INT A, VAR INT B) SAVE\nCTABDEF(C,VA,3,1)\nG1 VA=0 C=0\nCTABEND\nCTABDEF(X,VA,5,1)\nG1 VA=0 X=1\nCTABEND\nRET\n";
        let tables = table_definitions(text);
        assert_eq!(tables.len(), 2);
        assert!(tables[0].starts_with("PROC P(") && tables[0].contains("CTABDEF(C,VA,3,1)"));
        assert!(tables[1].contains("CTABDEF(X,VA,5,1)") && !tables[1].contains("C=0"));
    }
}
