#![deny(unsafe_code)]
#![warn(missing_docs)]

//! `solidtex serve`: the HTTP voxel service.
//!
//! It keeps precomputed candidates resident and answers requests for
//! slices, oblique cuts, regions and bricks by synthesizing only their
//! dependency set, with tiles shared in one byte-bounded cache. The engine
//! knows nothing about HTTP; this module maps routes onto it:
//!
//! - [`config`]: flags and `SOLIDTEX_*` variables ([`ServeArgs`]).
//! - [`spec`]: what a texture is made of and its content id.
//! - `store`: where textures are kept: the data directory, written
//!   atomically and durably, or an S3-compatible object store.
//! - [`registry`]: textures, their status and background precomputes;
//!   `regions`: region textures, two of them sharing space.
//! - `jobs`: the bounded synthesis queue (backpressure → 503);
//!   `decodes`: the bound on decoding uploaded images.
//! - `listen`: connections: header and idle timeouts, a connection cap;
//!   `conn_io`: their sockets as hyper sees them.
//! - [`routes`]: the router, handlers and middleware.
//! - `host`: the `Host` allow-list.
//! - [`memory`]: the server's own bound on its resident memory.
//! - [`metrics`], `process`, `error`, `query`, `peak_alloc`: the supporting
//!   pieces.
//!
//! [`Server::bind`] lists the data directory and listens; its textures are
//! loaded in the background, each served as soon as it is loaded, and a
//! request for one not loaded yet waits for the start to finish (up to
//! `--pending-wait`, then 503 `starting`); [`Server::run`]
//! stops accepting when its shutdown future resolves and returns once the
//! requests in flight have been answered.

pub(crate) mod background;
pub mod config;
pub(crate) mod conn_io;
pub(crate) mod decodes;
pub(crate) mod error;
pub(crate) mod host;
pub(crate) mod jobs;
pub(crate) mod listen;
pub mod memory;
pub mod metrics;
pub mod openapi;
pub(crate) mod panics;
pub mod peak_alloc;
pub(crate) mod process;
pub mod query;
pub(crate) mod regions;
pub mod registry;
pub mod routes;
pub mod spec;
pub(crate) mod store;

pub use config::{LogFormat, ServeArgs};
pub use error::ApiError;
pub use store::local::write_atomic;

use anyhow::Context;
use registry::Registry;
use routes::{AppState, Shared};
use solidtex_core::TileCache;
use spec::{Planes, TextureParams, TextureSpec};
use std::future::Future;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

/// Id under which the bundled exemplar is registered.
pub const DEFAULT_ID: &str = "default";

/// A bound, loaded server, ready to run.
pub struct Server {
    listener: tokio::net::TcpListener,
    state: AppState,
    limits: listen::Limits,
}

impl Server {
    /// Opens the data directory, brings its textures back, registers the
    /// bundled exemplar (when configured) and binds the listener.
    pub async fn bind(args: &ServeArgs) -> anyhow::Result<Server> {
        // Fixed-size answers must fit the per-request work budget.
        for (what, edge) in [("bricks", args.brick_size), ("chunks", args.chunk_size)] {
            let voxels = u64::from(edge).pow(3);
            let budget = args.max_request_voxels.min(args.max_request_work);
            if voxels > budget {
                anyhow::bail!(
                    "{what} of edge {edge} ({voxels} voxels) exceed the request budget of {budget} voxels"
                );
            }
        }
        let allowed_hosts = host::AllowedHosts::resolve(&args.allowed_hosts, args.addr)
            .map_err(|e| anyhow::anyhow!("--allowed-hosts: {e}"))?;
        let cors_origins = args
            .cors_origins
            .iter()
            .map(|o| {
                axum::http::HeaderValue::from_str(o).with_context(|| format!("CORS origin `{o}`"))
            })
            .collect::<anyhow::Result<_>>()?;
        // Bound first: an instance that cannot listen touches nothing.
        let listener = tokio::net::TcpListener::bind(args.addr)
            .await
            .with_context(|| format!("binding {}", args.addr))?;
        let store = open_store(args).await?;
        let cache = Arc::new(TileCache::new(
            usize::try_from(args.cache_bytes).unwrap_or(usize::MAX),
        ));
        let metrics = Arc::new(metrics::Metrics::new(cache.clone()));
        // Every allocation of the precompute threads is counted, so that
        // each precompute's peak is measured.
        let meter = crate::peak_alloc::Meter::leaked();
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(args.resolved_precompute_threads())
            .thread_name(|i| format!("precompute-{i}"))
            .start_handler(move |_| meter.attach())
            .build()
            .context("starting the precompute pool")?;
        let registry = Arc::new(
            Registry::new(
                store,
                cache,
                metrics.clone(),
                args.max_precomputes,
                args.precompute_queue,
                pool,
            )
            .with_storage_limits(args.max_textures as usize, args.max_stored_bytes)
            .with_memory_limit(args.max_resident_bytes)
            .with_precompute_memory(args.max_precompute_bytes, meter)
            .with_startup_wait(Duration::from_secs_f64(args.pending_wait)),
        );
        // Listed before anything is served, so that an unreadable storage
        // stops the start; loaded in the background, so that liveness and
        // the textures loaded so far answer at once.
        let found = {
            let r = registry.clone();
            tokio::task::spawn_blocking(move || r.scan())
                .await?
                .context("reading the data directory")?
        };
        tokio::spawn(bring_back(
            registry.clone(),
            found,
            args.default_texture,
            Duration::from_secs_f64(args.store_poll),
        ));
        let jobs = jobs::Jobs::new(
            args.max_jobs,
            args.queue,
            std::time::Duration::from_secs_f64(args.max_queue_wait),
            metrics.clone(),
        )
        .with_work_budget(args.max_request_work);
        let decodes = decodes::Decodes::new(
            args.max_decode_bytes,
            std::thread::available_parallelism().map_or(2, |n| n.get()),
            Duration::from_secs_f64(args.max_queue_wait),
        );
        let state = Arc::new(Shared {
            regions: Arc::new(regions::Regions::new(registry.store())),
            registry,
            jobs,
            decodes,
            metrics,
            brick_size: args.brick_size,
            chunk_size: args.chunk_size,
            max_request_voxels: args.max_request_voxels,
            max_request_work: args.max_request_work,
            background: Arc::new(background::Background::new(
                args.export_queue,
                args.max_export_work,
                args.max_export_bytes,
                Duration::from_secs(args.export_ttl),
            )),
            max_export_voxels: args.max_export_voxels,
            max_export_work: args.max_export_work,
            chunk_compression: args.chunk_compression,
            max_upload_bytes: usize::try_from(args.max_upload_bytes).unwrap_or(usize::MAX),
            token: args.token.clone().filter(|t| !t.is_empty()),
            cors_origins,
            default_texture: args.default_texture,
            pending_wait: std::time::Duration::from_secs_f64(args.pending_wait),
            body_timeout: Duration::from_secs_f64(args.body_timeout),
            allowed_hosts,
        });
        tracing::info!(
            addr = %listener.local_addr()?,
            store = %state.registry.location(),
            "server listening; stored textures loading"
        );
        let limits = listen::Limits {
            header_timeout: Duration::from_secs_f64(args.header_timeout),
            idle_timeout: Duration::from_secs_f64(args.idle_timeout),
            max_connections: listen::fit_descriptor_limit(
                usize::try_from(args.max_connections).unwrap_or(usize::MAX),
            ),
            max_head_bytes: routes::MAX_HEAD_BYTES,
            max_headers: routes::HYPER_MAX_HEADERS,
        };
        Ok(Server {
            listener,
            state,
            limits,
        })
    }

    /// Resolves once every stored texture is brought back and the bundled
    /// one registered (what `/readyz` waits for besides the bundled
    /// texture's precompute).
    pub async fn loaded(&self) {
        self.state.registry.wait_recovered().await;
    }

    /// The bound address (useful with port 0).
    pub fn local_addr(&self) -> std::io::Result<SocketAddr> {
        self.listener.local_addr()
    }

    /// The state handlers share (for tests).
    pub fn state(&self) -> AppState {
        self.state.clone()
    }

    /// Serves until `shutdown` resolves, then stops accepting and returns
    /// once in-flight requests are answered.
    pub fn run(
        self,
        shutdown: impl Future<Output = ()> + Send + 'static,
    ) -> impl Future<Output = anyhow::Result<()>> + Send + 'static {
        // Boxed here, so the serving loop is compiled once, in this crate,
        // and not again for each caller's kind of shutdown future.
        self.run_boxed(Box::pin(shutdown))
    }

    async fn run_boxed(self, shutdown: listen::Shutdown) -> anyhow::Result<()> {
        let metrics = self.state.metrics.clone();
        let app = routes::router(self.state);
        listen::serve(self.listener, app, self.limits, metrics, shutdown).await;
        Ok(())
    }
}

/// Brings back the stored textures `found`, then registers the bundled
/// exemplar (when `default_texture`) and follows deletions by other
/// servers every `store_poll`.
async fn bring_back(
    registry: Arc<Registry>,
    found: Vec<store::Found>,
    default_texture: bool,
    store_poll: Duration,
) {
    let t0 = std::time::Instant::now();
    let r = registry.clone();
    match tokio::task::spawn_blocking(move || r.recover(found)).await {
        Ok(todo) => registry.resume(todo),
        Err(e) => tracing::error!(error = %e, "bringing back the stored textures failed"),
    }
    registry.follow_deletes(store_poll);
    if default_texture {
        let spec = TextureSpec {
            planes: Planes::Single(solidtex_core::bundled::exemplar()),
            params: TextureParams::default(),
        };
        if let Err(e) = registry
            .submit(Some(DEFAULT_ID), spec, Some(DEFAULT_ID.to_string()))
            .await
        {
            // `/readyz` answers `default_missing` from now on.
            tracing::error!(error = %ApiError::from(e), "could not register the default texture");
        }
    }
    registry.set_recovered();
    tracing::info!(
        textures = registry.list().len(),
        seconds = t0.elapsed().as_secs_f64(),
        "stored textures loaded"
    );
}

/// The storage `args` name: the data directory, or a shared bucket.
async fn open_store(args: &ServeArgs) -> anyhow::Result<Arc<dyn store::Storage>> {
    if let Some(url) = &args.store {
        let opts = store::s3::S3Options {
            url: url.clone(),
            endpoint: args.s3_endpoint.clone(),
            region: args.s3_region.clone(),
        };
        let runtime = tokio::runtime::Handle::current();
        let s = tokio::task::spawn_blocking(move || store::s3::ObjectStorage::open(&opts, runtime))
            .await?
            .with_context(|| format!("opening the object store {url}"))?;
        return Ok(Arc::new(s));
    }
    let data_dir = args.resolved_data_dir();
    let d = data_dir.clone();
    let s = tokio::task::spawn_blocking(move || store::local::DataDir::open(&d))
        .await?
        .with_context(|| format!("opening data directory {}", data_dir.display()))?;
    Ok(Arc::new(s))
}

/// Resolves on SIGINT or SIGTERM.
pub async fn shutdown_signal() {
    let ctrl_c = async {
        if let Err(e) = tokio::signal::ctrl_c().await {
            tracing::error!(error = %e, "cannot listen for SIGINT");
            std::future::pending::<()>().await;
        }
    };
    #[cfg(unix)]
    let term = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(e) => {
                tracing::error!(error = %e, "cannot listen for SIGTERM");
                std::future::pending::<()>().await;
            }
        }
    };
    #[cfg(not(unix))]
    let term = std::future::pending::<()>();
    tokio::select! {
        _ = ctrl_c => {},
        _ = term => {},
    }
    tracing::info!("shutdown requested: finishing requests in flight");
}

fn init_tracing(args: &ServeArgs) {
    use tracing_subscriber::EnvFilter;
    let filter = EnvFilter::try_new(&args.log).unwrap_or_else(|_| EnvFilter::new("info"));
    // Colour only for a person at a terminal, never into files.
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .with_writer(std::io::stderr);
    let _ = match args.log_format {
        LogFormat::Pretty => builder.try_init(),
        LogFormat::Json => builder
            .json()
            .flatten_event(true)
            .with_current_span(true)
            .try_init(),
    };
}

/// Entry point of `solidtex serve`: sets up logging, the synthesis pool and
/// the async runtime, serves until SIGINT/SIGTERM, then waits up to the
/// shutdown timeout for requests in flight. Prints
/// `solidtex listening on http://ADDR` on stdout once accepting.
pub fn serve_main(args: ServeArgs) -> anyhow::Result<()> {
    // Heap in use is reported beside resident memory (two relaxed atomic
    // operations per allocation).
    crate::peak_alloc::start();
    init_tracing(&args);
    if args.worker_threads > 0 {
        rayon::ThreadPoolBuilder::new()
            .num_threads(args.worker_threads)
            .thread_name(|i| format!("synth-{i}"))
            .build_global()
            .context("starting the synthesis pool")?;
    }
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(args.http_threads as usize)
        .thread_name("http")
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    let timeout = Duration::from_secs(args.shutdown_timeout);
    let result = runtime.block_on(async move {
        let server = Server::bind(&args).await?;
        let addr = server.local_addr()?;
        println!("solidtex listening on http://{addr}");
        use std::io::Write;
        let _ = std::io::stdout().flush();
        let (tx, rx) = tokio::sync::oneshot::channel::<()>();
        let serving = tokio::spawn(server.run(async move {
            let _ = rx.await;
        }));
        shutdown_signal().await;
        let _ = tx.send(());
        match tokio::time::timeout(timeout, serving).await {
            Ok(r) => r.context("server task")?,
            Err(_) => {
                tracing::warn!(
                    seconds = timeout.as_secs(),
                    "requests still in flight at shutdown timeout"
                );
                Ok(())
            }
        }
    });
    // Background precomputes are abandoned (they restart from the data
    // directory next time); don't wait for them.
    runtime.shutdown_timeout(Duration::from_millis(100));
    tracing::info!("stopped");
    result
}
