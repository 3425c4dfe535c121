// sqlx::migrate! embeds the files under migrations/ at compile time; a proc macro cannot tell
// cargo which files it read, so this asks cargo to rebuild when that folder changes.
fn main() {
    println!("cargo:rerun-if-changed=migrations");
}
