//! `drawcal keys`: API keys on the service's database, for the first admin
//! key and for operators without a browser. `create` prints the key alone
//! on stdout (it is not stored, not shown again).

use clap::{Args, Subcommand};

use super::error::CliError;
use crate::http::keys;
use crate::store::Store;

/// `drawcal keys`.
#[derive(Debug, Args)]
pub struct KeysArgs {
    /// What to do.
    #[command(subcommand)]
    pub action: KeysAction,
    /// The service's database (as `serve --database`).
    #[arg(
        long,
        env = "DATABASE_URL",
        default_value = "sqlite://./drawcal.db",
        global = true
    )]
    pub database: String,
}

/// Key actions.
#[derive(Debug, Subcommand)]
pub enum KeysAction {
    /// Create a key; prints it alone on stdout.
    Create {
        /// Who will hold it (unique): what it does is recorded under it.
        #[arg(long)]
        name: String,
        /// reader, operator, engineer or admin.
        #[arg(long)]
        role: String,
        /// When it stops working (2027-06-30 or an RFC 3339 time).
        #[arg(long)]
        expires_at: Option<String>,
        /// A site the key is limited to (repeat for several): it reaches
        /// only the robots there. Default: every site.
        #[arg(long = "site")]
        sites: Vec<String>,
    },
    /// List the keys (never their secrets).
    List,
    /// Revoke a key by id: it is refused from now on.
    Revoke {
        /// The key's id (`keys list`).
        id: i64,
    },
}

/// Run `drawcal keys`.
pub fn run(a: KeysArgs) -> Result<(), CliError> {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| CliError::Service(e.into()))?;
    rt.block_on(async move {
        let store = Store::connect(&a.database)
            .await
            .map_err(|e| CliError::Service(e.into()))?;
        let fail = |e: crate::http::error::ApiError| CliError::Usage(e.to_string());
        // The actor of what the command line does: the machine's operator.
        let actor = "drawcal keys (command line)";
        match a.action {
            KeysAction::Create {
                name,
                role,
                expires_at,
                sites,
            } => {
                let created = keys::create(&store, actor, &name, &role, expires_at, &sites)
                    .await
                    .map_err(fail)?;
                eprintln!(
                    "key {} '{}' ({}) created; it is shown once, below",
                    created.key.id, created.key.name, created.key.role
                );
                println!("{}", created.secret);
            }
            KeysAction::List => {
                let list = store.list_keys().await.map_err(|e| fail(e.into()))?;
                println!("id\tname\trole\tprefix\tcreated_at\texpires_at\trevoked_at");
                for k in list {
                    println!(
                        "{}\t{}\t{}\t{}\t{}\t{}\t{}",
                        k.id,
                        k.name,
                        k.role,
                        k.prefix,
                        k.created_at,
                        k.expires_at.as_deref().unwrap_or("-"),
                        k.revoked_at.as_deref().unwrap_or("-")
                    );
                }
            }
            KeysAction::Revoke { id } => {
                let k = store
                    .revoke_key(id, actor)
                    .await
                    .map_err(|e| fail(e.into()))?;
                eprintln!("key {id} '{}' revoked", k.name);
            }
        }
        store.close().await;
        Ok(())
    })
}
