//! Rows packed against an earlier row: a table program (and its learning) or a learning
//! state is compressed with the plain text of the previous row of the same (machine, lobe)
//! as zstd dictionary, since consecutive ones differ only in some digits. `base_id` names
//! that row and `chain_depth` counts the rows behind it; every [`MAX_DEPTH`]-th row is packed
//! alone, so a read decompresses at most that many rows. A base row is never changed once a
//! row is packed against it (the only rewrite, of the newest learning state, skips rows
//! that are a base).

use super::codec::{CODEC_PACKED, CODEC_PLAIN};
use super::error::StoreError;
use super::pack::unpack_text;

/// Rows in a chain, the row packed alone included.
pub(crate) const MAX_DEPTH: i64 = 16;

/// A packed table and its fields: (plain text column, packed column, field name).
pub(crate) struct Chained {
    pub(crate) table: &'static str,
    pub(crate) fields: &'static [(&'static str, &'static str)],
}

pub(crate) const TABLE_VERSIONS: Chained = Chained {
    table: "table_versions",
    fields: &[
        ("program_text", "program_packed"),
        ("learning_params_json", "learning_packed"),
    ],
};

pub(crate) const LEARNING_STATES: Chained = Chained {
    table: "learning_states",
    fields: &[("state_json", "state_packed")],
};

/// One row of a chain as read.
pub(crate) struct Link {
    pub(crate) codec: i64,
    pub(crate) texts: Vec<Option<String>>,
    pub(crate) packs: Vec<Option<Vec<u8>>>,
}

impl Chained {
    /// The rows from the one packed alone up to row `$1`, oldest first. A base is always an
    /// older row (`p.id < chain.id`), which also ends the recursion on a damaged row.
    pub(crate) fn sql(&self) -> String {
        let t = self.table;
        let columns: Vec<String> = self
            .fields
            .iter()
            .map(|(text, packed)| format!("r.{text}, r.{packed}"))
            .collect();
        format!(
            "WITH RECURSIVE chain(id, base_id, depth) AS ( \
             SELECT id, base_id, 0 FROM {t} WHERE id = $1 \
             UNION ALL SELECT p.id, p.base_id, chain.depth + 1 FROM {t} p \
             JOIN chain ON p.id = chain.base_id WHERE p.id < chain.id) \
             SELECT r.codec, {} FROM chain JOIN {t} r ON r.id = chain.id \
             ORDER BY chain.depth DESC",
            columns.join(", ")
        )
    }

    /// The plain texts of the last link, decoding each link with the one before.
    pub(crate) fn resolve(&self, links: &[Link]) -> Result<Vec<String>, StoreError> {
        let mut plain: Vec<String> = vec![String::new(); self.fields.len()];
        if links.is_empty() {
            return Err(StoreError::invalid(
                self.table,
                "chain of packed rows is empty",
            ));
        }
        for (depth, link) in links.iter().enumerate() {
            for (i, &(text_col, packed_col)) in self.fields.iter().enumerate() {
                plain[i] = match (link.codec, &link.texts[i], &link.packs[i]) {
                    (CODEC_PLAIN, Some(text), _) => text.clone(),
                    // The first link was packed alone; each later one against its base.
                    (CODEC_PACKED, _, Some(blob)) => {
                        let dictionary = if depth == 0 { "" } else { plain[i].as_str() };
                        unpack_text(packed_col, blob, dictionary)?
                    }
                    (codec, _, _) => {
                        return Err(StoreError::invalid(
                            text_col,
                            format!("codec {codec} row of {} without its text", self.table),
                        ));
                    }
                };
            }
        }
        Ok(plain)
    }
}

/// Reads the chain ending at row `$id` of `$chained` with `$exec` (a pool or transaction).
macro_rules! fetch_chain {
    ($store:expr, $exec:expr, $chained:expr, $id:expr) => {{
        let chained = &$chained;
        let rows = sqlx::query(&chained.sql())
            .bind($id)
            .fetch_all($exec)
            .await
            .map_err($store.db_error("reading packed history"))?;
        let mut links = Vec::with_capacity(rows.len());
        for row in &rows {
            let mut texts = Vec::new();
            let mut packs = Vec::new();
            for i in 0..chained.fields.len() {
                let text: Option<String> = sqlx::Row::try_get(row, 1 + 2 * i)
                    .map_err($crate::store::error::db_error("reading packed history"))?;
                let pack: Option<Vec<u8>> = sqlx::Row::try_get(row, 2 + 2 * i)
                    .map_err($crate::store::error::db_error("reading packed history"))?;
                texts.push(text);
                packs.push(pack);
            }
            links.push($crate::store::chain::Link {
                codec: sqlx::Row::try_get(row, 0)
                    .map_err($crate::store::error::db_error("reading packed history"))?,
                texts,
                packs,
            });
        }
        chained.resolve(&links)?
    }};
}
pub(crate) use fetch_chain;

/// Where a new row of (machine, lobe) goes in its chain: `(base_id, chain_depth)` and the
/// base's plain texts (the dictionaries), read with `$exec` from the newest row.
macro_rules! next_link {
    ($store:expr, $exec:expr, $chained:expr, $machine:expr, $lobe:expr) => {{
        let chained = &$chained;
        let newest: Option<(i64, i64)> = sqlx::query_as(&format!(
            "SELECT id, chain_depth FROM {} WHERE machine = $1 AND lobe = $2 \
             ORDER BY id DESC LIMIT 1",
            chained.table
        ))
        .bind($machine)
        .bind($lobe)
        .fetch_optional(&mut *$exec)
        .await
        .map_err($store.db_error("reading packed history"))?;
        match newest {
            Some((id, depth)) if depth + 1 < $crate::store::chain::MAX_DEPTH => {
                let plain = $crate::store::chain::fetch_chain!($store, &mut *$exec, chained, id);
                (Some(id), depth + 1, plain)
            }
            _ => (None, 0, vec![String::new(); chained.fields.len()]),
        }
    }};
}
pub(crate) use next_link;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::pack::pack_text;

    /// A chain whose rows were packed by builds with different formats (zstd only, then
    /// numbers against the parent, then zstd again) reads back every row exactly: each link is
    /// decoded by its own format byte against its parent's plain text.
    #[test]
    fn a_chain_of_mixed_formats_reads_back() {
        let texts: Vec<String> = (0..3)
            .map(|v| {
                (0..40)
                    .map(|k| format!("X={:.4}\n", 7.0 + 0.01 * k as f64 + 0.0003 * v as f64))
                    .collect()
            })
            .collect();
        let plain = |t: &str, d: &str| {
            let mut out = vec![1u8];
            out.extend(
                zstd::bulk::Compressor::with_dictionary(3, d.as_bytes())
                    .unwrap()
                    .compress(t.as_bytes())
                    .unwrap(),
            );
            out
        };
        let packs = [
            plain(&texts[0], ""),
            pack_text("program_packed", &texts[1], &texts[0]).unwrap(),
            plain(&texts[2], &texts[1]),
        ];
        assert_eq!(packs[1][0], 2, "the middle row uses the numbers format");
        for end in 1..=3 {
            let links: Vec<Link> = packs[..end]
                .iter()
                .map(|p| Link {
                    codec: CODEC_PACKED,
                    texts: vec![None],
                    packs: vec![Some(p.clone())],
                })
                .collect();
            let chained = Chained {
                table: "t",
                fields: &[("program_text", "program_packed")],
            };
            assert_eq!(
                chained.resolve(&links).unwrap(),
                vec![texts[end - 1].clone()]
            );
        }
    }
}
