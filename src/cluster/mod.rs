//! Several `camloop run` instances on one PostgreSQL: each machine is owned by one instance
//! at a time through a lease in the database ([`lease`]), with a fencing epoch that every
//! push carries ([`crate::share::Fence`]). This module holds the leases and the plan of
//! which machines an instance should hold; the service's cluster task carries it out.
//!
//! The plan: every instance holds at most its fair share, `ceil(machines / live
//! instances)`. Which machines: rendezvous hashing (each instance ranks the machines by a
//! hash of its name and theirs), so the same instance prefers the same machines and a
//! returning instance gets back roughly what it had, without any instance telling another.

pub mod lease;

pub use lease::{Epoch, LeaseError, LeaseRow, Leases, Renewed};

/// What an instance should do with its machines this round.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Plan {
    /// Machines to stop and release (more than the fair share is held), least preferred
    /// first.
    pub shed: Vec<String>,
    /// Free machines to try to take, most preferred first, as many as the fair share has
    /// room for (some may be taken by another instance first).
    pub take: Vec<String>,
}

/// The machines one instance may hold when `live` instances share `machines`.
pub(crate) fn fair_share(machines: usize, live: usize) -> usize {
    machines.div_ceil(live.max(1))
}

/// The instance's preference for a machine (higher: more wanted). FNV-1a over both names:
/// stable across builds and platforms, unlike the standard library's hasher.
pub(crate) fn preference(instance: &str, machine: &str) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in instance.bytes().chain([0]).chain(machine.bytes()) {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    // FNV's low bits mix poorly for short keys: a final avalanche (from splitmix64).
    h ^= h >> 30;
    h = h.wrapping_mul(0xbf58_476d_1ce4_e5b9);
    h ^= h >> 27;
    h = h.wrapping_mul(0x94d0_49bb_1331_11eb);
    h ^ (h >> 31)
}

/// The round's plan for `instance`, holding `held`, among `all` machines of which `free`
/// have no live lease, with `live` instances alive.
pub fn plan(instance: &str, all: &[String], held: &[String], free: &[String], live: usize) -> Plan {
    let fair = fair_share(all.len(), live);
    let rank = |list: &[String]| {
        let mut v: Vec<String> = list.to_vec();
        v.sort_by_key(|m| std::cmp::Reverse(preference(instance, m)));
        v
    };
    let mut shed = rank(held);
    let keep = shed.len().min(fair);
    let shed: Vec<String> = shed.split_off(keep).into_iter().rev().collect();
    let room = fair.saturating_sub(held.len());
    let take = rank(free).into_iter().take(room).collect();
    Plan { shed, take }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(n: usize) -> Vec<String> {
        (1..=n).map(|i| format!("M{i:02}")).collect()
    }

    #[test]
    fn the_fair_share_rounds_up() {
        assert_eq!(fair_share(30, 3), 10);
        assert_eq!(fair_share(30, 2), 15);
        assert_eq!(fair_share(31, 3), 11);
        assert_eq!(fair_share(5, 0), 5);
    }

    /// Three instances taking turns from nothing end with 10 machines each, every machine
    /// owned once; when one dies the two left take its 10; when it returns, each of them
    /// sheds exactly what it needs to.
    #[test]
    fn rounds_converge_to_an_even_split_and_rebalance() {
        let all = names(30);
        let instances = ["a", "b", "c"];
        let mut held: std::collections::BTreeMap<&str, Vec<String>> =
            instances.iter().map(|i| (*i, Vec::new())).collect();
        fn round<'a>(
            all: &[String],
            held: &mut std::collections::BTreeMap<&'a str, Vec<String>>,
            alive: &[&'a str],
        ) {
            for i in alive {
                let owned: Vec<String> = held.values().flatten().cloned().collect();
                let free: Vec<String> =
                    all.iter().filter(|m| !owned.contains(m)).cloned().collect();
                let p = plan(i, all, &held[i], &free, alive.len());
                let mine = held.get_mut(i).unwrap();
                mine.retain(|m| !p.shed.contains(m));
                mine.extend(p.take);
            }
        }
        round(&all, &mut held, &instances);
        let counts: Vec<usize> = held.values().map(Vec::len).collect();
        assert_eq!(counts, vec![10, 10, 10]);
        // c dies: its leases expire, a and b share its machines.
        held.get_mut("c").unwrap().clear();
        round(&all, &mut held, &["a", "b"]);
        assert_eq!(held["a"].len() + held["b"].len(), 30);
        assert_eq!((held["a"].len(), held["b"].len()), (15, 15));
        // c returns: a and b shed 5 each in one round, c takes them in the next.
        round(&all, &mut held, &instances);
        round(&all, &mut held, &instances);
        let counts: Vec<usize> = held.values().map(Vec::len).collect();
        assert_eq!(counts, vec![10, 10, 10]);
        let mut every: Vec<String> = held.values().flatten().cloned().collect();
        every.sort();
        assert_eq!(every, all, "every machine owned exactly once");
    }

    #[test]
    fn an_instance_sheds_its_least_preferred_machines() {
        let all = names(4);
        let p = plan("a", &all, &all, &[], 2);
        assert_eq!(p.shed.len(), 2);
        let kept: Vec<&String> = all.iter().filter(|m| !p.shed.contains(m)).collect();
        for k in kept {
            for s in &p.shed {
                assert!(preference("a", k) > preference("a", s));
            }
        }
    }
}
