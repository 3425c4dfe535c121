//! The provenance block of a table program, and retargeting a rendered table program to
//! another table number (rollback re-delivers an old version under the free number).

use thiserror::Error;

use super::comment_text;
use super::settings::Provenance;
use super::syntax::{Line, Statement};
use super::table::NUMBER_VAR;

/// Start of the comment line that names the table number and form.
pub(crate) const TABLE_COMMENT: &str = "; curve table ";

/// Keys of the provenance lines, in the order they are written.
const KEYS: [&str; 7] = [
    "camloop version",
    "table version",
    "parent version",
    "created utc",
    "recipe",
    "feature",
    "correction sha256",
];

/// The first provenance line's start, as written.
const FIRST_LINE: &str = "; camloop version: ";

/// The provenance lines without the leading `; `, values made printable by
/// [`comment_text`].
pub(crate) fn provenance_lines(p: &Provenance) -> Vec<String> {
    let parent = p
        .parent_version
        .map_or_else(|| "none".to_owned(), |v| format!("v{v}"));
    let values = [
        comment_text(&p.camloop_version),
        format!("v{}", p.table_version),
        parent,
        comment_text(&p.created_utc),
        comment_text(&p.recipe),
        comment_text(&p.feature),
        p.correction_sha256.to_string(),
    ];
    KEYS.iter()
        .zip(values)
        .map(|(key, value)| format!("{key}: {value}"))
        .collect()
}

/// Why a table program cannot be retargeted. Lines are 1-based.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum RetargetError {
    #[error("table number 0: curve table numbers start at 1")]
    NumberZero,
    #[error(
        "the program has no `{NUMBER_VAR}=` assignment: it cannot tell its caller the table number"
    )]
    NoAssignment,
    #[error("the program has no CTABDEF line")]
    NoCtabdef,
    #[error("the program has no PROC line to put the provenance after")]
    NoProc,
    #[error("line {line}: a second {what}, the first is on line {first_line}")]
    Repeated {
        what: &'static str,
        line: usize,
        first_line: usize,
    },
    #[error("line {line}: {what} `{text}` is not a table number")]
    BadNumber {
        what: &'static str,
        line: usize,
        text: String,
    },
    #[error(
        "line {assignment_line} assigns {NUMBER_VAR}={assigned} but line {ctabdef_line} defines table {defined}: the caller would couple the wrong table"
    )]
    Disagree {
        assignment_line: usize,
        assigned: u32,
        ctabdef_line: usize,
        defined: u32,
    },
}

/// One line of the program being retargeted.
enum Found {
    Assignment(u32),
    Ctabdef(u32),
    Other,
}

/// `text` (a table program written by camloop) defining table `number` instead: the
/// `CL_TNO=` assignment, the `CTABDEF` number and the `; curve table n:` comment change
/// together; with `provenance`, the provenance block after `PROC` is replaced (or added, for
/// a program written before provenance existed). Everything else is kept byte for byte.
///
/// Refused when `number` is 0, when the assignment or `CTABDEF` is missing or repeated, or
/// when they disagree in `text`: such a program would make the caller couple a table it
/// did not define.
pub fn retarget_table_program(
    text: &str,
    number: u32,
    provenance: Option<&Provenance>,
) -> Result<String, RetargetError> {
    if number == 0 {
        return Err(RetargetError::NumberZero);
    }
    let lines: Vec<&str> = text.lines().collect();
    let (assignment, ctabdef) = find_numbers(&lines)?;
    let ((assignment_line, assigned), (ctabdef_line, defined)) = (
        assignment.ok_or(RetargetError::NoAssignment)?,
        ctabdef.ok_or(RetargetError::NoCtabdef)?,
    );
    if assigned != defined {
        return Err(RetargetError::Disagree {
            assignment_line,
            assigned,
            ctabdef_line,
            defined,
        });
    }
    let proc_index = lines.iter().position(|l| l.starts_with("PROC "));
    if provenance.is_some() && proc_index.is_none() {
        return Err(RetargetError::NoProc);
    }
    // The old block, replaced when a new provenance is given: it starts with its first key
    // right after PROC, so a comment line that merely looks like a key is never taken.
    let old_block = match (provenance, proc_index) {
        (Some(_), Some(p)) if lines.get(p + 1).is_some_and(|l| l.starts_with(FIRST_LINE)) => {
            let len = lines[p + 1..]
                .iter()
                .take_while(|l| is_provenance_line(l))
                .count();
            p + 1..p + 1 + len
        }
        _ => 0..0,
    };
    let mut out: Vec<String> = Vec::with_capacity(lines.len() + KEYS.len());
    for (index, raw) in lines.iter().enumerate() {
        let line = index + 1;
        if old_block.contains(&index) {
            continue;
        }
        if line == assignment_line {
            out.push(replace_assignment(raw, number));
        } else if line == ctabdef_line {
            out.push(replace_ctabdef(raw, number));
        } else if let Some(rest) = raw.strip_prefix(TABLE_COMMENT)
            && let Some((n, tail)) = rest.split_once(':')
            && n.parse::<u32>().is_ok()
        {
            out.push(format!("{TABLE_COMMENT}{number}:{tail}"));
        } else {
            out.push((*raw).to_owned());
        }
        if let Some(p) = provenance
            && Some(index) == proc_index
        {
            out.extend(provenance_lines(p).into_iter().map(|l| format!("; {l}")));
        }
    }
    let mut joined = out.join("\n");
    joined.push('\n');
    Ok(joined)
}

/// (line, number) of the `CL_TNO=` assignment and of `CTABDEF`, each at most once.
type Numbers = (Option<(usize, u32)>, Option<(usize, u32)>);

fn find_numbers(lines: &[&str]) -> Result<Numbers, RetargetError> {
    let (mut assignment, mut ctabdef) = (None, None);
    for (index, raw) in lines.iter().enumerate() {
        let line = index + 1;
        let (slot, what, n) = match classify(raw, line)? {
            Found::Assignment(n) => (&mut assignment, "table number assignment", n),
            Found::Ctabdef(n) => (&mut ctabdef, "CTABDEF", n),
            Found::Other => continue,
        };
        if let Some((first_line, _)) = *slot {
            return Err(RetargetError::Repeated {
                what,
                line,
                first_line,
            });
        }
        *slot = Some((line, n));
    }
    Ok((assignment, ctabdef))
}

fn classify(raw: &str, line: usize) -> Result<Found, RetargetError> {
    let l = Line::new(line, raw);
    let assigns = l
        .code
        .strip_prefix(NUMBER_VAR)
        .is_some_and(|r| r.trim_start().starts_with('='));
    let (what, text) = if assigns {
        let value = l.code.split_once('=').map_or("", |(_, v)| v);
        ("table number assignment", value)
    } else if l.code.starts_with("CTABDEF(") {
        ("CTABDEF", l.code.split(',').nth(2).unwrap_or(""))
    } else {
        return Ok(Found::Other);
    };
    let bad = || RetargetError::BadNumber {
        what,
        line,
        text: text.trim().to_owned(),
    };
    match l.statement() {
        Ok(Some(Statement::CtabDef(def))) => Ok(Found::Ctabdef(def.number)),
        Ok(Some(Statement::Assign { target, value })) if target == NUMBER_VAR => value
            .number()
            .filter(|n| n.fract() == 0.0 && (0.0..=f64::from(u32::MAX)).contains(n))
            .map(|n| Found::Assignment(n as u32))
            .ok_or_else(bad),
        _ => Err(bad()),
    }
}

fn is_provenance_line(raw: &str) -> bool {
    raw.strip_prefix("; ")
        .and_then(|r| r.split_once(": "))
        .is_some_and(|(key, _)| KEYS.contains(&key))
}

/// `CL_TNO=<n>` with its comment kept.
fn replace_assignment(raw: &str, number: u32) -> String {
    match raw.split_once(';') {
        Some((_, comment)) => format!("{NUMBER_VAR}={number} ;{comment}"),
        None => format!("{NUMBER_VAR}={number}"),
    }
}

/// `CTABDEF(X,C,<n>,…)` with the other arguments and any comment kept.
fn replace_ctabdef(raw: &str, number: u32) -> String {
    let (code, comment) = match raw.split_once(';') {
        Some((code, comment)) => (code.trim_end(), Some(comment)),
        None => (raw.trim_end(), None),
    };
    let args = code.strip_prefix("CTABDEF(").unwrap_or(code);
    let mut parts: Vec<String> = args.split(',').map(str::to_owned).collect();
    if let Some(third) = parts.get_mut(2) {
        *third = number.to_string();
    }
    let mut out = format!("CTABDEF({}", parts.join(","));
    if let Some(c) = comment {
        out.push_str(" ;");
        out.push_str(c);
    }
    out
}
