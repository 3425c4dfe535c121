//! `camloop tls self-signed`: a development certificate and key for `http.tls_cert` and
//! `http.tls_key`.

use anyhow::Context;
use std::io::Write;
use std::path::{Path, PathBuf};

#[derive(Debug, clap::Args)]
pub struct TlsArgs {
    #[command(subcommand)]
    command: TlsCommand,
}

#[derive(Debug, clap::Subcommand)]
enum TlsCommand {
    /// A self-signed certificate (cert.pem) and its key (key.pem, readable by its owner only)
    /// for development and tests: clients must be told to trust it (curl --cacert cert.pem).
    SelfSigned(SelfSignedArgs),
}

#[derive(Debug, clap::Args)]
struct SelfSignedArgs {
    /// A host name or address the certificate is for (repeat for more; default: localhost,
    /// 127.0.0.1 and ::1).
    #[arg(long = "name")]
    names: Vec<String>,
    /// Folder to write cert.pem and key.pem into.
    #[arg(long, default_value = ".")]
    out: PathBuf,
    /// Replace an existing pair.
    #[arg(long)]
    force: bool,
}

pub(crate) fn run_tls(args: TlsArgs) -> anyhow::Result<()> {
    let TlsCommand::SelfSigned(a) = args.command;
    let names = match a.names.is_empty() {
        true => vec!["localhost".into(), "127.0.0.1".into(), "::1".into()],
        false => a.names,
    };
    let (cert, key) = crate::service::http::self_signed(&names)?;
    std::fs::create_dir_all(&a.out).with_context(|| a.out.display().to_string())?;
    let (cert_path, key_path) = (a.out.join("cert.pem"), a.out.join("key.pem"));
    write_new(&key_path, &key, 0o600, a.force)?;
    write_new(&cert_path, &cert, 0o644, a.force)?;
    println!(
        "wrote {} and {} (key readable by its owner only) for {}\n\
         in the config: [http] tls_cert = \"{}\", tls_key = \"{}\"",
        cert_path.display(),
        key_path.display(),
        names.join(", "),
        cert_path.display(),
        key_path.display()
    );
    Ok(())
}

/// Writes `text` to a new file with `mode` (an existing one only with `force`).
fn write_new(path: &Path, text: &str, mode: u32, force: bool) -> anyhow::Result<()> {
    let mut options = std::fs::OpenOptions::new();
    options.write(true);
    match force {
        true => options.create(true).truncate(true),
        false => options.create_new(true),
    };
    #[cfg(unix)]
    std::os::unix::fs::OpenOptionsExt::mode(&mut options, mode);
    #[cfg(not(unix))]
    let _ = mode;
    let mut file = options.open(path).with_context(|| {
        format!(
            "{}: cannot write (exists? --force replaces it)",
            path.display()
        )
    })?;
    #[cfg(unix)]
    std::fs::set_permissions(path, std::os::unix::fs::PermissionsExt::from_mode(mode))
        .with_context(|| path.display().to_string())?;
    file.write_all(text.as_bytes())
        .with_context(|| path.display().to_string())
}
