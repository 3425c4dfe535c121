//! Machine leases in PostgreSQL: who owns which machine, until when, and the fencing epoch
//! of each ownership. Times are the database's (`now()`), so the instances' clocks never
//! have to agree. The tables are the cluster's own coordination state (not history), made
//! by the first instance that joins.

use crate::names::MachineName;
use sqlx::Row;
use sqlx::postgres::{PgConnectOptions, PgPool, PgPoolOptions};
use std::time::Duration;

/// Instances starting together make the tables one at a time, under a transaction lock: a
/// `CREATE TABLE IF NOT EXISTS` racing another can fail on the catalogue's unique index.
/// The `incarnation` column came later: a table made before it gets it once. The catalogue
/// is asked first because `ALTER TABLE` locks the table whole even when the column exists,
/// and every connect (each instance's, each keeper's) would then stall every renewal.
const SCHEMA: &str = "\
BEGIN;\
SELECT pg_advisory_xact_lock(7340925001);\
CREATE TABLE IF NOT EXISTS camloop_leases (\
  machine TEXT PRIMARY KEY,\
  owner TEXT NOT NULL,\
  epoch BIGINT NOT NULL,\
  expires_at TIMESTAMPTZ NOT NULL,\
  incarnation TEXT NOT NULL DEFAULT '');\
CREATE TABLE IF NOT EXISTS camloop_instances (\
  instance TEXT PRIMARY KEY,\
  seen_until TIMESTAMPTZ NOT NULL);\
DO $$ BEGIN \
  IF NOT EXISTS (SELECT 1 FROM information_schema.columns \
    WHERE table_name = 'camloop_leases' AND column_name = 'incarnation') THEN \
    ALTER TABLE camloop_leases ADD COLUMN incarnation TEXT NOT NULL DEFAULT ''; \
  END IF; \
END $$;\
COMMIT";

/// A lease operation failed; the database said why.
#[derive(Debug, thiserror::Error)]
#[error("cluster lease database: cannot {op}: {source}")]
pub struct LeaseError {
    op: &'static str,
    #[source]
    source: sqlx::Error,
}

fn op(op: &'static str) -> impl FnOnce(sqlx::Error) -> LeaseError {
    move |source| LeaseError { op, source }
}

/// A lease's fencing epoch: one above the previous owner's, carried by every push of the
/// owner (the machine's fence file, the share's manifest). `BIGINT` in the database,
/// written there and read back by [`Epoch::db`] and [`Epoch::from_db`].
#[derive(
    Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default, serde::Serialize, serde::Deserialize,
)]
#[serde(transparent)]
pub struct Epoch(pub u64);

/// Debug as the number, as epochs showed before they were typed.
impl std::fmt::Debug for Epoch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        std::fmt::Debug::fmt(&self.0, f)
    }
}

impl Epoch {
    /// The next owner's epoch.
    pub fn next(self) -> Epoch {
        Epoch(self.0 + 1)
    }

    /// The column's value (epochs start at 1 and rise by one a take: far below `i64::MAX`).
    pub(crate) fn db(self) -> i64 {
        self.0 as i64
    }

    pub(crate) fn from_db(value: i64) -> Epoch {
        Epoch(value as u64)
    }
}

impl std::fmt::Display for Epoch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        std::fmt::Display::fmt(&self.0, f)
    }
}

/// A machine name read back from the lease table: one that fails the rule (a row written
/// outside camloop) is a decode error naming the column, never a panic.
fn machine_of(text: String) -> Result<MachineName, sqlx::Error> {
    MachineName::try_from(text).map_err(|e| sqlx::Error::ColumnDecode {
        index: "camloop_leases.machine".into(),
        source: Box::new(e),
    })
}

/// One machine's lease as the database holds it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LeaseRow {
    pub machine: MachineName,
    pub owner: String,
    pub epoch: Epoch,
    /// Whether it is still running (not expired, not released).
    pub live: bool,
}

/// What [`Leases::renew`] did.
#[derive(Debug, Clone, Default)]
pub struct Renewed {
    /// The leases renewed: machine and epoch.
    pub renewed: Vec<(MachineName, Epoch)>,
    /// Live leases under this instance's name that it does not run, released.
    pub leftovers: Vec<MachineName>,
}

/// This instance's handle on the lease tables.
#[derive(Debug, Clone)]
pub struct Leases {
    pool: PgPool,
    instance: String,
    /// This process among all that ever ran under the instance's name: every lease it wins
    /// carries it, so a lease left by an earlier process of the same name is told apart from
    /// one this process has just won (see [`Leases::renew`]).
    incarnation: String,
    lease_ms: i64,
}

/// This process's incarnation: its pid and start time, unique among the processes of one
/// instance name (a restart gets a new pid or a later time).
fn incarnation() -> String {
    static ME: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    ME.get_or_init(|| {
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_nanos())
            .unwrap_or(0);
        format!("{}-{nanos}", std::process::id())
    })
    .clone()
}

impl Leases {
    /// Connects (a small pool of its own, apart from the history's) and makes the tables.
    pub async fn connect(url: &str, instance: &str, lease: Duration) -> Result<Self, LeaseError> {
        Self::connect_with(url, instance, lease, &[]).await
    }

    /// The lease keeper's connection: as [`Leases::connect`], with `synchronous_commit` off.
    /// The keeper only renews, says it is alive and releases; with the server's default a
    /// renewal's commit waits for the write-ahead log's flush, behind every history write
    /// of every instance (2.1 s per commit on a shared, busy disk with 1,500 machines, more
    /// than the quarter lease a renewal may take, so 649 machines were stopped for leases
    /// their instance still held). Losing such a commit in a server crash is safe: the row
    /// goes back to the renewal before, which still runs at least three quarters of a lease
    /// past the moment this one was asked, while the owner stops its machines half a lease
    /// after it; a lost heartbeat or release only runs out sooner or later. Taking a lease
    /// (its epoch) stays on the cluster task's connection, durable.
    pub(crate) async fn connect_keeper(
        url: &str,
        instance: &str,
        lease: Duration,
    ) -> Result<Self, LeaseError> {
        Self::connect_with(url, instance, lease, &[("synchronous_commit", "off")]).await
    }

    async fn connect_with(
        url: &str,
        instance: &str,
        lease: Duration,
        settings: &[(&str, &str)],
    ) -> Result<Self, LeaseError> {
        // No statement may hold a round up longer than a quarter lease (a database that
        // hangs rather than refuses): the machines held must be stopped in time.
        let timeout = (lease / 4).as_millis().to_string();
        let mut options = vec![("statement_timeout", timeout.as_str())];
        options.extend_from_slice(settings);
        let options = url
            .parse::<PgConnectOptions>()
            .map_err(op("read the database URL"))?
            .options(options);
        let pool = PgPoolOptions::new()
            .max_connections(3)
            .acquire_timeout(lease / 4)
            .connect_with(options)
            .await
            .map_err(op("connect"))?;
        sqlx::raw_sql(SCHEMA)
            .execute(&pool)
            .await
            .map_err(op("create the lease tables"))?;
        Ok(Self {
            pool,
            instance: instance.to_string(),
            incarnation: incarnation(),
            lease_ms: lease.as_millis() as i64,
        })
    }

    pub fn instance(&self) -> &str {
        &self.instance
    }

    /// Says this instance is alive for one more lease; returns how many instances are.
    pub(crate) async fn heartbeat(&self) -> Result<usize, LeaseError> {
        sqlx::query(
            "INSERT INTO camloop_instances (instance, seen_until) \
             VALUES ($1, now() + $2 * interval '1 millisecond') \
             ON CONFLICT (instance) DO UPDATE SET seen_until = EXCLUDED.seen_until",
        )
        .bind(&self.instance)
        .bind(self.lease_ms)
        .execute(&self.pool)
        .await
        .map_err(op("record the heartbeat"))?;
        self.live_instances().await
    }

    /// How many instances are alive (their heartbeat has not run out); at least one.
    pub(crate) async fn live_instances(&self) -> Result<usize, LeaseError> {
        let live: i64 =
            sqlx::query_scalar("SELECT count(*) FROM camloop_instances WHERE seen_until > now()")
                .fetch_one(&self.pool)
                .await
                .map_err(op("count the live instances"))?;
        Ok(live.max(1) as usize)
    }

    /// Takes `machine` when nobody holds it (never leased, expired or released): returns the
    /// new epoch, one above the last owner's. `None`: another instance holds it.
    pub(crate) async fn acquire(&self, machine: &MachineName) -> Result<Option<Epoch>, LeaseError> {
        let epoch: Option<i64> = sqlx::query_scalar(
            "INSERT INTO camloop_leases (machine, owner, epoch, expires_at, incarnation) \
             VALUES ($1, $2, 1, now() + $3 * interval '1 millisecond', $4) \
             ON CONFLICT (machine) DO UPDATE SET owner = EXCLUDED.owner, \
               epoch = camloop_leases.epoch + 1, expires_at = EXCLUDED.expires_at, \
               incarnation = EXCLUDED.incarnation \
             WHERE camloop_leases.expires_at <= now() RETURNING epoch",
        )
        .bind(machine.as_str())
        .bind(&self.instance)
        .bind(self.lease_ms)
        .bind(&self.incarnation)
        .fetch_optional(&self.pool)
        .await
        .map_err(op("acquire a lease"))?;
        Ok(epoch.map(Epoch::from_db))
    }

    /// Raises the epoch of a lease this instance holds to `to` (the machine's fence was
    /// already higher: a lease table made again from nothing). Returns the new epoch, or
    /// `None` when the lease is no longer this instance's.
    pub(crate) async fn raise_epoch(
        &self,
        machine: &MachineName,
        epoch: Epoch,
        to: Epoch,
    ) -> Result<Option<Epoch>, LeaseError> {
        let raised: Option<i64> = sqlx::query_scalar(
            "UPDATE camloop_leases SET epoch = $4 \
             WHERE machine = $1 AND owner = $2 AND epoch = $3 AND expires_at > now() \
             RETURNING epoch",
        )
        .bind(machine.as_str())
        .bind(&self.instance)
        .bind(epoch.db())
        .bind(to.db())
        .fetch_optional(&self.pool)
        .await
        .map_err(op("raise a lease's epoch"))?;
        Ok(raised.map(Epoch::from_db))
    }

    /// Extends the leases this instance runs (`held`: machine and epoch) and returns those
    /// renewed: one missing from the answer was lost (it expired; another instance may own
    /// it). Every live lease under this instance's name that an earlier process won (a
    /// restart within the lease) runs nowhere and is released, so that it is taken at once
    /// rather than renewed forever; those come back second. A lease this process won is
    /// never taken for such a leftover, however recently it was won: the two are told apart
    /// by the process's incarnation, not by a list that a concurrent win could outrun.
    pub(crate) async fn renew(&self, held: &[(MachineName, Epoch)]) -> Result<Renewed, LeaseError> {
        let machines: Vec<&str> = held.iter().map(|(m, _)| m.as_str()).collect();
        let epochs: Vec<i64> = held.iter().map(|(_, e)| e.db()).collect();
        let rows = sqlx::query(
            "UPDATE camloop_leases SET expires_at = now() + $2 * interval '1 millisecond' \
             WHERE owner = $1 AND expires_at > now() \
               AND (machine, epoch) IN (SELECT * FROM unnest($3::text[], $4::bigint[])) \
             RETURNING machine, epoch",
        )
        .bind(&self.instance)
        .bind(self.lease_ms)
        .bind(&machines)
        .bind(&epochs)
        .fetch_all(&self.pool)
        .await
        .map_err(op("renew the leases"))?;
        let renewed = rows
            .iter()
            .map(|r| Ok((machine_of(r.get(0))?, Epoch::from_db(r.get(1)))))
            .collect::<Result<_, sqlx::Error>>()
            .map_err(op("read the renewed leases"))?;
        let leftovers: Vec<String> = sqlx::query_scalar(
            "UPDATE camloop_leases SET expires_at = now() - interval '1 millisecond' \
             WHERE owner = $1 AND expires_at > now() AND incarnation <> $2 \
             RETURNING machine",
        )
        .bind(&self.instance)
        .bind(&self.incarnation)
        .fetch_all(&self.pool)
        .await
        .map_err(op("release leftover leases"))?;
        let leftovers = leftovers
            .into_iter()
            .map(machine_of)
            .collect::<Result<_, _>>()
            .map_err(op("read the leftover leases"))?;
        Ok(Renewed { renewed, leftovers })
    }

    /// Gives `machine` up at once (its loop has stopped): any instance may take it now.
    pub async fn release(&self, machine: &MachineName, epoch: Epoch) -> Result<(), LeaseError> {
        sqlx::query(
            "UPDATE camloop_leases SET expires_at = now() - interval '1 millisecond' \
             WHERE machine = $1 AND owner = $2 AND epoch = $3",
        )
        .bind(machine.as_str())
        .bind(&self.instance)
        .bind(epoch.db())
        .execute(&self.pool)
        .await
        .map_err(op("release a lease"))?;
        Ok(())
    }

    /// This instance leaves: it no longer counts among the live ones.
    pub async fn leave(&self) -> Result<(), LeaseError> {
        sqlx::query("DELETE FROM camloop_instances WHERE instance = $1")
            .bind(&self.instance)
            .execute(&self.pool)
            .await
            .map_err(op("leave"))?;
        Ok(())
    }

    /// Every lease, for the API and the tests.
    pub async fn all(&self) -> Result<Vec<LeaseRow>, LeaseError> {
        let rows = sqlx::query(
            "SELECT machine, owner, epoch, expires_at > now() FROM camloop_leases ORDER BY machine",
        )
        .fetch_all(&self.pool)
        .await
        .map_err(op("read the leases"))?;
        rows.iter()
            .map(|r| {
                Ok(LeaseRow {
                    machine: machine_of(r.get(0)).map_err(op("read the leases"))?,
                    owner: r.get(1),
                    epoch: Epoch::from_db(r.get(2)),
                    live: r.get(3),
                })
            })
            .collect()
    }
}
