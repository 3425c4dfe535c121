//! The service's start-up check, before it touches the database or a share: every file the
//! config names (recipes with their lift tables, DBC files) is read and validated, no two
//! machines share a folder, and the HTTP listener is bound (and kept, for the server). Every
//! problem is reported at once, with the config line that names the file or folder.

use super::{Config, ConfigError, ConfigProblem, GaugeSection, MachineSection};
use crate::names::{FeatureName, MachineName};
use crate::recipe::{FeatureSetup, Recipe};
use std::collections::HashMap;
use std::path::{Component, Path, PathBuf};

/// A configuration that passed every check, with what the checks produced.
#[derive(Debug)]
pub struct Checked {
    pub config: Config,
    /// One per `[[machines]]`, in the file's order.
    pub machines: Vec<CheckedMachine>,
    /// The API's listener, already bound (so a port in use is found before anything starts).
    pub listener: std::net::TcpListener,
}

/// One machine: its checked name and the lobes or pins it grinds, loaded from its recipe,
/// with the machine's C speed applied.
#[derive(Debug, Clone)]
pub struct CheckedMachine {
    pub name: MachineName,
    pub recipe_path: PathBuf,
    pub setups: Vec<FeatureSetup>,
    /// The simulator's C speed is set in the config (else it grinds at the recipe's).
    pub sim_c_speed_explicit: bool,
}

/// The features machine `m` grinds, by name, in recipe order: every one of the recipe's,
/// or those `lobe` / `features` name. A name the recipe lacks is an error.
pub fn machine_features(recipe: &Recipe, m: &MachineSection) -> Result<Vec<FeatureName>, String> {
    let all: Vec<&FeatureName> = recipe.features().collect();
    let chosen: &[FeatureName] = match (&m.lobe, &m.features) {
        (Some(_), Some(_)) => return Err("give lobe or features, not both".into()),
        (Some(one), None) => std::slice::from_ref(one),
        (None, Some(list)) if list.is_empty() => return Err("features is empty".into()),
        (None, Some(list)) => list,
        (None, None) => return Ok(all.into_iter().cloned().collect()),
    };
    if let Some(missing) = chosen.iter().find(|c| !all.contains(c)) {
        return Err(format!(
            "no lobe or pin {missing} (has: {})",
            recipe.feature_names().join(", ")
        ));
    }
    Ok(all
        .into_iter()
        .filter(|n| chosen.contains(n))
        .cloned()
        .collect())
}

/// The feature names of machine `m` as its recipe gives them (empty when the recipe cannot
/// be read: the start-up check reports that).
pub fn configured_features(config: &Config, m: &MachineSection) -> Vec<FeatureName> {
    Recipe::load(&config.resolve(&m.recipe))
        .ok()
        .and_then(|r| machine_features(&r, m).ok())
        .unwrap_or_default()
}

fn machine_setups(
    recipe: &Recipe,
    recipe_path: &Path,
    m: &MachineSection,
) -> anyhow::Result<Vec<FeatureSetup>> {
    let names = machine_features(recipe, m).map_err(|e| anyhow::anyhow!(e))?;
    let mut setups = Vec::with_capacity(names.len());
    for name in names {
        let mut setup = recipe.feature_setup(recipe_path, &name)?;
        if let Some(rpm) = m.c_speed_rpm {
            anyhow::ensure!(
                rpm.is_finite() && rpm > 0.0,
                "c_speed_rpm = {rpm}: must be a number > 0"
            );
            setup.limits.c_speed_rpm = rpm;
        }
        setups.push(setup);
    }
    Ok(setups)
}

/// Parses `text` (the file `file`) and checks everything, config and named files and
/// listener, reporting every problem at once.
pub fn load(
    text: &str,
    file: &Path,
    env: impl Fn(&str) -> Option<String>,
) -> Result<Checked, ConfigError> {
    let (config, mut problems) = Config::read(text, file, env);
    let error = |problems| ConfigError {
        file: file.display().to_string(),
        problems,
    };
    let Some(config) = config else {
        return Err(error(problems));
    };
    match check(config) {
        Ok(checked) if problems.is_empty() => Ok(checked),
        Ok(_) => Err(error(problems)),
        Err(e) => {
            problems.extend(e.problems);
            problems.sort_by_key(|p| p.line.unwrap_or(usize::MAX));
            Err(error(problems))
        }
    }
}

/// Checks what a parsed config names: recipes, lobes, DBC files, folders, the listener.
pub fn check(config: Config) -> Result<Checked, ConfigError> {
    let mut problems = Vec::new();
    let mut machines = Vec::new();
    for (i, m) in config.machines.iter().enumerate() {
        if let Some(machine) = check_machine(&config, i, m, &mut problems) {
            machines.push(machine);
        }
    }
    problems.extend(shared_folders(&config));
    if let Err(p) = super::network_exposure(
        &config.http,
        config.auth.anonymous_read(config.http.listen),
        &config.lines,
    ) {
        problems.push(p);
    }
    let listener = match bind(config.http.listen) {
        Ok(l) => Some(l),
        Err(e) => {
            problems.push(ConfigProblem::at(
                config.line("http.listen"),
                format!("http.listen: cannot listen on {}: {e}", config.http.listen),
            ));
            None
        }
    };
    match listener {
        Some(listener) if problems.is_empty() => Ok(Checked {
            config,
            machines,
            listener,
        }),
        _ => {
            problems.sort_by_key(|p| p.line.unwrap_or(usize::MAX));
            Err(ConfigError {
                file: config.file.display().to_string(),
                problems,
            })
        }
    }
}

/// One `[[machines]]` entry: its recipe and features, its gauge's DBC file. Problems go to
/// `problems`; the machine comes back only when its name and features are sound.
fn check_machine(
    config: &Config,
    i: usize,
    m: &MachineSection,
    problems: &mut Vec<ConfigProblem>,
) -> Option<CheckedMachine> {
    let line = |key: &str| config.line(&format!("machines[{i}].{key}"));
    let label = format!("machines.{}", m.name);
    let recipe_path = config.resolve(&m.recipe);
    let setups = match Recipe::load(&recipe_path) {
        // The whole cycle needs a gauge that tells a measurement before the finish from a
        // finished part's: the drop folder does (`<name>.in-process.csv`), and so does the
        // simulator (it hands the service its in-process measurements as such). CAN and
        // serial frames carry no stage: refused rather than ignored.
        Ok(recipe)
            if recipe
                .cycle
                .as_ref()
                .is_some_and(|c| c.program == crate::core::cycle::CycleProgram::Whole)
                && matches!(
                    m.gauge,
                    GaugeSection::Can { .. } | GaugeSection::Serial { .. }
                ) =>
        {
            problems.push(ConfigProblem::at(
                line("recipe"),
                format!(
                    "{label}.recipe: its [cycle] program = \"whole\" needs a gauge that says which measurement is taken before the finish, and CAN and serial frames carry no stage; set program = \"table-only\" (the cycle is checked, the machine builder's cycle grinds) or use kind = \"drop\" (<name>.in-process.csv) or \"sim\""
                ),
            ));
            None
        }
        Ok(recipe) => match machine_setups(&recipe, &recipe_path, m) {
            Ok(setups) => Some(setups),
            Err(e) => {
                let key = if m.features.is_some() {
                    "features"
                } else {
                    "lobe"
                };
                let at = if line(key).is_some() { key } else { "recipe" };
                problems.push(ConfigProblem::at(line(at), format!("{label}.{at}: {e:#}")));
                None
            }
        },
        Err(e) => {
            problems.push(ConfigProblem::at(
                line("recipe"),
                format!("{label}.recipe: {e:#}"),
            ));
            None
        }
    };
    if let GaugeSection::Can { dbc, .. } = &m.gauge {
        let names = crate::gauge::GaugeSignalNames::default();
        if let Err(e) = crate::gauge::GaugeDbc::load(&config.resolve(dbc), &names) {
            problems.push(ConfigProblem::at(
                line("gauge.dbc"),
                format!("{label}.gauge.dbc: {e}"),
            ));
        }
    }
    Some(CheckedMachine {
        name: m.name.clone(),
        recipe_path,
        setups: setups?,
        sim_c_speed_explicit: config.sets(&format!("machines[{i}].gauge.grinder.c_speed_rpm")),
    })
}

/// Connections the kernel queues while every slot is taken (`http.max_connections`), as
/// many as tokio's own bind would allow.
const BACKLOG: i32 = 1024;

/// Binds the API's listener (address reuse as std and tokio set it, a backlog of
/// [`BACKLOG`]) without needing a runtime.
fn bind(addr: std::net::SocketAddr) -> std::io::Result<std::net::TcpListener> {
    use socket2::{Domain, Protocol, Socket, Type};
    let socket = Socket::new(Domain::for_address(addr), Type::STREAM, Some(Protocol::TCP))?;
    #[cfg(unix)]
    socket.set_reuse_address(true)?;
    socket.bind(&addr.into())?;
    socket.listen(BACKLOG)?;
    Ok(socket.into())
}

/// Two machines writing one share (or reading one drop folder) overwrite each other's
/// programs (or steal each other's files): refused, naming both and the folder.
fn shared_folders(config: &Config) -> Vec<ConfigProblem> {
    let mut claims: HashMap<PathBuf, (&MachineName, &str)> = HashMap::new();
    let mut problems = Vec::new();
    for (i, m) in config.machines.iter().enumerate() {
        let mut folders = vec![("share", &m.share)];
        if let GaugeSection::Drop { folder, .. } = &m.gauge {
            folders.push(("gauge.folder", folder));
        }
        for (key, folder) in folders {
            let resolved = config.resolve(folder);
            let normal = normalise(&resolved);
            let what = match key {
                "share" => "share",
                _ => "drop folder",
            };
            if let Some((other, other_what)) = claims.get(&normal) {
                problems.push(ConfigProblem::at(
                    config.line(&format!("machines[{i}].{key}")),
                    format!(
                        "machines.{}.{key}: {} is also the {other_what} of machine {other}; \
                         each machine needs a folder of its own",
                        m.name,
                        resolved.display(),
                    ),
                ));
            } else {
                claims.insert(normal, (&m.name, what));
            }
        }
    }
    problems
}

/// The folder as the file system will see it: absolute, `.` and `..` resolved, and symbolic
/// links in the part that exists followed.
fn normalise(path: &Path) -> PathBuf {
    let absolute = if path.is_absolute() {
        path.to_path_buf()
    } else {
        std::env::current_dir().unwrap_or_default().join(path)
    };
    let mut clean = PathBuf::new();
    for c in absolute.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                clean.pop();
            }
            other => clean.push(other),
        }
    }
    // Follow links in the longest part that exists; the rest is taken as written.
    let mut existing = clean.clone();
    let mut rest = Vec::new();
    while !existing.exists() {
        match existing.file_name() {
            Some(name) => rest.push(name.to_owned()),
            None => return clean,
        }
        if !existing.pop() {
            return clean;
        }
    }
    let mut real = existing.canonicalize().unwrap_or(existing);
    real.extend(rest.iter().rev());
    real
}
