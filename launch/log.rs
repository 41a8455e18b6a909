//! What this process prints on stderr besides its results: the launcher library's console
//! ([`glissade::console`]: its events printed verbatim, notes only with `--verbose`, "warning: "
//! and "error: " before warnings and errors) and, with `RUST_LOG` set, the log of this process and
//! its libraries (Zenoh) in tracing's format.

use std::fmt::Write as _;
use tracing::field::{Field, Visit};
use tracing::{Event, Level, Subscriber};
use tracing_subscriber::layer::{Context, SubscriberExt};
use tracing_subscriber::util::SubscriberInitExt;
use tracing_subscriber::Layer;

/// Prints the console's events.
struct Console;

/// The formatted message of an event.
#[derive(Default)]
struct Message(String);

impl Visit for Message {
    fn record_debug(&mut self, field: &Field, value: &dyn std::fmt::Debug) {
        if field.name() == "message" {
            let _ = write!(self.0, "{value:?}");
        }
    }
}

impl<S: Subscriber> Layer<S> for Console {
    fn on_event(&self, event: &Event<'_>, _: Context<'_, S>) {
        let level = *event.metadata().level();
        if level > Level::INFO && !glissade::console::verbose() {
            return;
        }
        let mut m = Message::default();
        event.record(&mut m);
        let prefix = match level {
            Level::ERROR => "error: ",
            Level::WARN => "warning: ",
            _ => "",
        };
        eprintln!("{prefix}{}", m.0);
    }
}

/// Installs the console and, with `RUST_LOG` set (tracing's filter syntax, e.g. `zenoh=warn` or
/// `zenoh_transport=debug`), the log of this process and its libraries. Node processes inherit
/// the variable, and the launcher forwards their lines.
pub(crate) fn install() -> anyhow::Result<()> {
    let log = match std::env::var_os("RUST_LOG") {
        None => None,
        Some(filter) => {
            let filter = filter
                .into_string()
                .map_err(|v| anyhow::anyhow!("RUST_LOG = {v:?} is not UTF-8"))?;
            // Zenoh logs a session's whole configuration, the bus password among it, at debug
            // level when it opens: that module is held at info whatever RUST_LOG asks. The
            // console's events are printed by the console only.
            let filter = tracing_subscriber::EnvFilter::try_new(&filter)
                .map_err(|e| anyhow::anyhow!("RUST_LOG = {filter:?} is not a tracing filter: {e}"))?
                .add_directive("zenoh::api::session=info".parse().expect("a valid directive"))
                .add_directive(
                    format!("{}=off", glissade::console::TARGET)
                        .parse()
                        .expect("a valid directive"),
                );
            Some(
                tracing_subscriber::fmt::layer()
                    .with_writer(std::io::stderr)
                    .with_ansi(false)
                    .with_filter(filter),
            )
        }
    };
    // Only the console's own events reach the console, at most at debug level: every other
    // callsite stays disabled (a static level check, as with no subscriber) unless RUST_LOG asks
    // for it.
    let console = || {
        Console.with_filter(
            tracing_subscriber::filter::Targets::new()
                .with_target(glissade::console::TARGET, tracing::level_filters::LevelFilter::DEBUG),
        )
    };
    match log {
        None => tracing_subscriber::registry().with(console()).try_init(),
        Some(log) => tracing_subscriber::registry().with(console()).with(log).try_init(),
    }
    .map_err(|e| anyhow::anyhow!("cannot install the console and log: {e}"))
}
