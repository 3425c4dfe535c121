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
                    .map_err($crate::error::db_error("reading packed history"))?;
                let pack: Option<Vec<u8>> = sqlx::Row::try_get(row, 2 + 2 * i)
                    .map_err($crate::error::db_error("reading packed history"))?;
                texts.push(text);
                packs.push(pack);
            }
            links.push($crate::chain::Link {
                codec: sqlx::Row::try_get(row, 0)
                    .map_err($crate::error::db_error("reading packed history"))?,
                texts,
                packs,
            });
        }
        chained.resolve(&links)?
    }};
}
pub(crate) use fetch_chain;

/// Plain texts of recently packed rows, so that a new row does not decode its parent's whole
/// chain again (at 3600 points that was up to 15 programs of 190 KB per table). An entry
/// serves only while the row's packed bytes in the database are the ones it was made from:
/// a base row never changes, so equal bytes over the same id mean equal texts. Anything else
/// (another instance wrote the row, a replaced learning state, a restored database) reads
/// the chain. Two rows per (table, machine, lobe): the newest and its base (what replacing
/// the newest learning state packs against).
#[derive(Debug, Default)]
pub(crate) struct ChainCache {
    rows: std::sync::Mutex<std::collections::HashMap<CacheKey, Vec<CachedRow>>>,
}

type CacheKey = (&'static str, String, String);

#[derive(Debug)]
struct CachedRow {
    id: i64,
    packs: Vec<Vec<u8>>,
    texts: Vec<String>,
}

/// Features whose rows are kept: past this many the cache starts again (it only saves work).
const CACHED_FEATURES: usize = 4096;

impl ChainCache {
    fn lock(
        &self,
    ) -> std::sync::MutexGuard<'_, std::collections::HashMap<CacheKey, Vec<CachedRow>>> {
        self.rows.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The texts of row `id` when its packed columns are still `packs`.
    pub(crate) fn get(
        &self,
        key: (&'static str, &str, &str),
        id: i64,
        packs: &[Option<Vec<u8>>],
    ) -> Option<Vec<String>> {
        let rows = self.lock();
        let row = rows
            .get(&(key.0, key.1.to_string(), key.2.to_string()))?
            .iter()
            .find(|r| r.id == id)?;
        let same = row.packs.len() == packs.len()
            && row
                .packs
                .iter()
                .zip(packs)
                .all(|(a, b)| Some(a) == b.as_ref());
        same.then(|| row.texts.clone())
    }

    /// Remembers row `id` (packed as `packs`, reading as `texts`) as the newest of its key.
    pub(crate) fn put(
        &self,
        key: (&'static str, &str, &str),
        id: i64,
        packs: Vec<Vec<u8>>,
        texts: Vec<String>,
    ) {
        let mut rows = self.lock();
        if rows.len() >= CACHED_FEATURES {
            rows.clear();
        }
        let kept = rows
            .entry((key.0, key.1.to_string(), key.2.to_string()))
            .or_default();
        kept.retain(|r| r.id != id);
        kept.push(CachedRow { id, packs, texts });
        let excess = kept.len().saturating_sub(2);
        kept.drain(..excess);
    }
}

/// The plain texts of row `$id` of (`$machine`, `$lobe`) in `$chained`: from the store's
/// [`ChainCache`] when the row still holds the packs it was cached with, else by reading its
/// chain (and caching them).
macro_rules! texts_of {
    ($store:expr, $exec:expr, $chained:expr, $machine:expr, $lobe:expr, $id:expr) => {{
        let chained = &$chained;
        let id: i64 = $id;
        let key: (&'static str, &str, &str) = (chained.table, $machine, $lobe);
        let packed: Vec<&str> = chained.fields.iter().map(|(_, p)| *p).collect();
        let row = sqlx::query(&format!(
            "SELECT {} FROM {} WHERE id = $1",
            packed.join(", "),
            chained.table
        ))
        .bind(id)
        .fetch_one(&mut *$exec)
        .await
        .map_err($store.db_error("reading packed history"))?;
        let mut packs: Vec<Option<Vec<u8>>> = Vec::with_capacity(packed.len());
        for i in 0..packed.len() {
            packs.push(
                sqlx::Row::try_get(&row, i)
                    .map_err($crate::error::db_error("reading packed history"))?,
            );
        }
        match $store.chains.get(key, id, &packs) {
            Some(texts) => texts,
            None => {
                let texts = $crate::chain::fetch_chain!($store, &mut *$exec, chained, id);
                if let Some(packs) = packs.into_iter().collect::<Option<Vec<_>>>() {
                    $store.chains.put(key, id, packs, texts.clone());
                }
                texts
            }
        }
    }};
}
pub(crate) use texts_of;

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
            Some((id, depth)) if depth + 1 < $crate::chain::MAX_DEPTH => {
                let plain = $crate::chain::texts_of!($store, $exec, chained, $machine, $lobe, id);
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
    use crate::pack::pack_text;

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
