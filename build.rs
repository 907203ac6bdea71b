// Re-embed the migrations (sqlx::migrate!) whenever they change.
fn main() {
    println!("cargo:rerun-if-changed=migrations/sqlite");
    println!("cargo:rerun-if-changed=migrations/postgres");
}
