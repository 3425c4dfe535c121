//! Reading a TOML file so that every problem comes out at once, each with its line: every
//! syntax error, every unknown key, and the first wrongly typed or missing value of each
//! top-level section or `[[machines]]` entry.
//!
//! serde stops at the first error. So the document is parsed into a spanned tree, and
//! deserialised again and again: an unknown key found is noted and removed from the tree;
//! a section with a bad value is noted and removed whole (so that its missing parts do not
//! come back as more errors), until the rest deserialises.

use super::ConfigProblem;
use serde::de::DeserializeOwned;
use std::collections::BTreeMap;
use std::ops::Range;
use toml::Spanned;
use toml::de::{DeTable, DeValue};

/// At most this many rounds: one per problem found, so far more than a config has.
const MAX_ROUNDS: usize = 500;

/// What a tolerant read gives: the value (when the rest deserialised), every problem, and
/// the line of every key left in the tree.
pub(crate) struct Read<T> {
    pub value: Option<T>,
    pub problems: Vec<ConfigProblem>,
    pub lines: Lines,
    /// Names of top-level keys whose value (a section or an array entry) was dropped
    /// because of a bad value: later checks on them would only repeat the problem.
    pub dropped: Vec<String>,
}

/// The line (1-based) of each key, by its dotted path: `http.listen`, `machines[1].name`;
/// a table's path gives its header's line.
#[derive(Debug, Clone, Default)]
pub struct Lines(BTreeMap<String, usize>);

impl Lines {
    /// The line of `path`, or of its nearest ancestor that has one.
    /// Whether the file sets exactly this key (no parent counts).
    pub fn has(&self, path: &str) -> bool {
        self.0.contains_key(path)
    }

    pub fn of(&self, path: &str) -> Option<usize> {
        let mut p = path;
        loop {
            if let Some(&l) = self.0.get(p) {
                return Some(l);
            }
            p = &p[..p.rfind(['.', '['])?];
        }
    }
}

/// The 1-based line of byte offset `at` in `text`.
pub(crate) fn line_of(text: &str, at: usize) -> usize {
    text[..at.min(text.len())].matches('\n').count() + 1
}

/// Deserialises `text` into `T`, collecting every problem instead of stopping at the first.
pub(crate) fn read<T: DeserializeOwned>(text: &str) -> Read<T> {
    let (mut root, errors) = DeTable::parse_recoverable(text);
    let mut problems: Vec<ConfigProblem> = Vec::new();
    for e in errors {
        let p = ConfigProblem {
            line: e.span().map(|s| line_of(text, s.start)),
            message: e.message().trim_end().to_string(),
        };
        if !problems.contains(&p) {
            problems.push(p);
        }
    }
    let mut read = Read {
        value: None,
        problems,
        lines: Lines::default(),
        dropped: Vec::new(),
    };
    if !read.problems.is_empty() {
        // A tree recovered from broken syntax would only add guesses.
        return read;
    }
    for _ in 0..MAX_ROUNDS {
        let error = match T::deserialize(toml::de::Deserializer::from(root.clone())) {
            Ok(value) => {
                read.value = Some(value);
                break;
            }
            Err(e) => e,
        };
        let message = error.message().trim_end().to_string();
        let span = error.span();
        let fixed = match (unknown_field(&message), span.clone()) {
            (Some(field), Some(span)) => remove_unknown(root.get_mut(), &span, field),
            (None, Some(span)) => drop_section(root.get_mut(), &span).map(|(key, at)| {
                read.dropped.push(key);
                at
            }),
            _ => None,
        };
        let at = fixed.clone().or(span);
        read.problems.push(ConfigProblem {
            line: at.map(|s| line_of(text, s.start)),
            message,
        });
        if fixed.is_none() {
            break;
        }
    }
    collect_lines(text, root.get_ref(), "", &mut read.lines.0);
    read
}

/// `unknown field `x`, expected …` → `x`.
fn unknown_field(message: &str) -> Option<&str> {
    let rest = message.strip_prefix("unknown field `")?;
    rest.split_once('`').map(|(field, _)| field)
}

/// Removes the key `field` from the table at `span` (or, when serde lost the exact place
/// inside an enum, from the first table below it that has it); returns the key's span.
fn remove_unknown(
    table: &mut DeTable<'_>,
    span: &Range<usize>,
    field: &str,
) -> Option<Range<usize>> {
    // The key itself is at `span` (a plain struct reports the key).
    let direct = table
        .iter()
        .find(|(k, _)| k.span() == *span && k.get_ref() == field)
        .map(|(k, _)| k.clone());
    if let Some(key) = direct {
        table.remove(&key);
        return Some(key.span());
    }
    for (_, value) in table.iter_mut() {
        let here = value.span() == *span;
        if let Some(found) = remove_in_value(value, span, field, here) {
            return Some(found);
        }
    }
    None
}

fn remove_in_value(
    value: &mut Spanned<DeValue<'_>>,
    span: &Range<usize>,
    field: &str,
    inside: bool,
) -> Option<Range<usize>> {
    match value.get_mut() {
        DeValue::Table(t) => {
            if inside && let Some(key) = first_key_named(t, field) {
                return remove_key_below(t, &key);
            }
            remove_unknown(t, span, field)
        }
        DeValue::Array(items) => items.iter_mut().find_map(|item| {
            let here = inside || item.span() == *span;
            remove_in_value(item, span, field, here)
        }),
        _ => None,
    }
}

/// The span of the first key named `field` in `table` or below it.
fn first_key_named(table: &DeTable<'_>, field: &str) -> Option<Range<usize>> {
    table.iter().find_map(|(k, v)| {
        if k.get_ref() == field {
            Some(k.span())
        } else if let DeValue::Table(t) = v.get_ref() {
            first_key_named(t, field)
        } else {
            None
        }
    })
}

/// Removes the key whose span is `key` from `table` or below it.
fn remove_key_below(table: &mut DeTable<'_>, key: &Range<usize>) -> Option<Range<usize>> {
    let found = table
        .iter()
        .find(|(k, _)| k.span() == *key)
        .map(|(k, _)| k.clone());
    if let Some(k) = found {
        table.remove(&k);
        return Some(k.span());
    }
    table.iter_mut().find_map(|(_, v)| match v.get_mut() {
        DeValue::Table(t) => remove_key_below(t, key),
        _ => None,
    })
}

/// Drops the top-level section (or array entry) holding `span`; returns the top-level key
/// and the span to report. `None` when the span is nowhere in the tree.
fn drop_section(root: &mut DeTable<'_>, span: &Range<usize>) -> Option<(String, Range<usize>)> {
    let mut found = None;
    for (key, value) in root.iter_mut() {
        // An array of tables first: its span is its first entry's header.
        if let DeValue::Array(items) = value.get_mut()
            && let Some(i) = items.iter().position(|item| contains_span(item, span))
        {
            found = Some((key.clone(), Some(i)));
            break;
        }
        if key.span() == *span || contains_span(value, span) {
            found = Some((key.clone(), None));
            break;
        }
    }
    let (key, index) = found?;
    let name = key.get_ref().to_string();
    match index {
        Some(i) => {
            if let Some(DeValue::Array(items)) = root.get_mut(&key).map(Spanned::get_mut) {
                // DeArray has no remove: rebuild it without entry i.
                let all = std::mem::replace(items, toml::de::DeArray::new());
                *items = all
                    .into_iter()
                    .enumerate()
                    .filter_map(|(j, item)| (j != i).then_some(item))
                    .collect();
            }
        }
        None => {
            root.remove(&key);
        }
    }
    Some((name, span.clone()))
}

/// Whether `span` is the span of `value` or of a key or value anywhere below it.
fn contains_span(value: &Spanned<DeValue<'_>>, span: &Range<usize>) -> bool {
    if value.span() == *span {
        return true;
    }
    match value.get_ref() {
        DeValue::Table(t) => t
            .iter()
            .any(|(k, v)| k.span() == *span || contains_span(v, span)),
        DeValue::Array(items) => items.iter().any(|item| contains_span(item, span)),
        _ => false,
    }
}

fn collect_lines(text: &str, table: &DeTable<'_>, prefix: &str, out: &mut BTreeMap<String, usize>) {
    for (key, value) in table.iter() {
        let path = if prefix.is_empty() {
            key.get_ref().to_string()
        } else {
            format!("{prefix}.{}", key.get_ref())
        };
        match value.get_ref() {
            DeValue::Table(t) => {
                out.insert(path.clone(), line_of(text, value.span().start));
                collect_lines(text, t, &path, out);
            }
            DeValue::Array(items) => {
                out.insert(path.clone(), line_of(text, key.span().start));
                for (i, item) in items.iter().enumerate() {
                    let item_path = format!("{path}[{i}]");
                    out.insert(item_path.clone(), line_of(text, item.span().start));
                    if let DeValue::Table(t) = item.get_ref() {
                        collect_lines(text, t, &item_path, out);
                    }
                }
            }
            _ => {
                out.insert(path, line_of(text, key.span().start));
            }
        }
    }
}
