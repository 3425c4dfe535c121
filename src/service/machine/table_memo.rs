//! Tables already computed in this process, by their exact inputs: a plant's machines of one
//! recipe open with the same nominal (or restored) tables, so each is computed once rather
//! than once per feature of every machine (at 500 machines × 8 lobes, 4,000 geometry and fit
//! runs became 2).
//!
//! A hit is only ever an input equal to one computed before (the lift table, the correction
//! and timing bit for bit, the geometry, the request and the limits), so the table is the
//! one [`compensate::current_table`] would compute; a refusal is not kept (it is computed
//! again, with its reason, every time).

use crate::core::compensate::{self, AxisLimits, Feature, GuardError, GuardedTable, TableRequest};
use crate::core::learn::LearningState;
use crate::core::lift::LiftTable;
use std::sync::{Mutex, OnceLock};

/// Entries kept: a plant has a few recipes of a few features each; past this the oldest go.
const KEPT: usize = 64;

/// Everything [`compensate::current_table`] reads.
#[derive(Debug, Clone)]
struct Key {
    nominal: LiftTable,
    correction_bits: Vec<u64>,
    timing_bits: u64,
    feature: Feature,
    request: TableRequest,
    limits: AxisLimits,
}

impl Key {
    fn new(state: &LearningState, lobe: &compensate::LobeLoop<'_>) -> Self {
        Self {
            nominal: lobe.nominal.clone(),
            correction_bits: state.correction_um.iter().map(|c| c.to_bits()).collect(),
            timing_bits: state.timing_correction_deg.to_bits(),
            feature: lobe.feature,
            request: lobe.request,
            limits: lobe.limits.clone(),
        }
    }

    fn matches(&self, state: &LearningState, lobe: &compensate::LobeLoop<'_>) -> bool {
        self.timing_bits == state.timing_correction_deg.to_bits()
            && self.correction_bits.len() == state.correction_um.len()
            && self
                .correction_bits
                .iter()
                .zip(&state.correction_um)
                .all(|(b, c)| *b == c.to_bits())
            && self.feature == lobe.feature
            && self.request == lobe.request
            && self.limits == *lobe.limits
            && self.nominal == *lobe.nominal
    }
}

/// The memo: a short list searched in order (a handful of entries in a plant).
#[derive(Default)]
pub(crate) struct TableMemo {
    entries: Mutex<Vec<(Key, GuardedTable)>>,
}

impl TableMemo {
    /// The process's memo.
    pub(crate) fn global() -> &'static TableMemo {
        static MEMO: OnceLock<TableMemo> = OnceLock::new();
        MEMO.get_or_init(TableMemo::default)
    }

    /// [`compensate::current_table`] for these inputs, computed once. The computation runs
    /// outside the lock, so features with other inputs are not held up by it.
    pub(crate) fn current_table(
        &self,
        state: &LearningState,
        lobe: &compensate::LobeLoop<'_>,
    ) -> Result<GuardedTable, GuardError> {
        if let Some(table) = self.find(state, lobe) {
            return Ok(table);
        }
        let table = compensate::current_table(state, lobe)?;
        let mut entries = self.lock();
        if entries.len() >= KEPT {
            entries.remove(0);
        }
        entries.push((Key::new(state, lobe), table.clone()));
        Ok(table)
    }

    fn find(&self, state: &LearningState, lobe: &compensate::LobeLoop<'_>) -> Option<GuardedTable> {
        let entries = self.lock();
        entries
            .iter()
            .find(|(k, _)| k.matches(state, lobe))
            .map(|(_, t)| t.clone())
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Vec<(Key, GuardedTable)>> {
        // Every change is one push or one remove: a panic elsewhere leaves it usable.
        self.entries.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Entries held (for tests).
    #[cfg(test)]
    fn len(&self) -> usize {
        self.lock().len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::recipe::{FeatureSetup, Recipe};
    use crate::service::machine::memory::LoopMemory;
    use std::path::Path;

    fn setups() -> Vec<FeatureSetup> {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/parts/demo-camshaft.toml");
        Recipe::load(&path).unwrap().feature_setups(&path).unwrap()
    }

    /// Tables compare by their debug text: every point, segment and figure, to the bit's
    /// shortest round-trip form.
    fn text(t: &GuardedTable) -> String {
        format!("{t:?}")
    }

    /// The demo shaft's four intake lobes share a lift file: the memo computes their nominal
    /// table once, and what it hands out is the table computed directly, for every lobe.
    #[test]
    fn equal_inputs_are_computed_once_and_give_the_direct_table() {
        let memo = TableMemo::default();
        let state = LoopMemory::new(250.0).newest_learning().clone();
        let setups = setups();
        for s in &setups {
            let direct = compensate::current_table(&state, &s.lobe_loop()).unwrap();
            let memo_table = memo.current_table(&state, &s.lobe_loop()).unwrap();
            assert_eq!(text(&memo_table), text(&direct), "{}", s.name);
        }
        // Intake and exhaust: two lift files, one table each for the whole shaft.
        assert_eq!(memo.len(), 2);
    }

    /// A correction one bit apart is another input: another entry, another table.
    #[test]
    fn a_correction_one_bit_apart_is_computed_again() {
        let memo = TableMemo::default();
        let setup = &setups()[0];
        let state = LoopMemory::new(250.0).newest_learning().clone();
        let first = memo.current_table(&state, &setup.lobe_loop()).unwrap();
        let mut moved = state.clone();
        moved.correction_um[90] = f64::from_bits(moved.correction_um[90].to_bits() + 1);
        let second = memo.current_table(&moved, &setup.lobe_loop()).unwrap();
        assert_eq!(memo.len(), 2);
        let direct = compensate::current_table(&moved, &setup.lobe_loop()).unwrap();
        assert_eq!(text(&second), text(&direct));
        // A 1 µm correction moves the table's points: the memo did not hand out the first.
        moved.correction_um[90] = 1.0;
        let third = memo.current_table(&moved, &setup.lobe_loop()).unwrap();
        assert_ne!(text(&third), text(&first));
    }

    /// A refusal is not kept: each call computes it again and says why.
    #[test]
    fn a_refused_table_is_not_kept() {
        let memo = TableMemo::default();
        let mut setup = setups().remove(0);
        setup.limits.velocity_mm_s = 0.001;
        let state = LoopMemory::new(250.0).newest_learning().clone();
        let direct = compensate::current_table(&state, &setup.lobe_loop()).unwrap_err();
        let refused = memo.current_table(&state, &setup.lobe_loop()).unwrap_err();
        assert_eq!(refused, direct);
        assert_eq!(memo.len(), 0);
    }
}
