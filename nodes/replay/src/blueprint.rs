//! The layout the view opens with: a blueprint sent on the recording stream before any data, so
//! the viewer shows these panels from the first message on and never rearranges them.
//!
//! - left, large: the structure (`subdomains/**`, the contact status points `interfaces/**`, the
//!   colour scale `legend/**`; not the traction arrows `tractions/**`) in a 3D view whose eye looks
//!   straight down on the plane z = 0, framed on the model and its legend;
//! - right, top: log10 η, log10 e_c and (with `--reference`) log10 of the traction error;
//! - right, bottom: the contact status counts (per iteration, and per time point of
//!   the final state);
//! - the time panel on the `iteration` timeline, following the data;
//!   switching it to `time` steps through the final state's time points.
//!
//! The Rust SDK's `rerun::blueprint` builders (0.36.3) cannot set a view's properties (its
//! `add_property` is crate-private), and a 2D view does not draw `Mesh3D`; so this module logs
//! the blueprint archetypes the SDK logs (viewport, containers, views, view contents, time
//! panel) itself, plus the 3D view's `EyeControls3D` (the eye straight above the model) and
//! `LineGrid3D` (hidden: the grid plane would cut through the mesh at z = 0).

use crate::legend::Frame;
use crate::{rerr, ReplayError};
use rerun::external::re_log_types::{BlueprintActivationCommand, LogMsg};
use rerun::external::re_sdk_types::blueprint::archetypes as bp;
use rerun::external::re_sdk_types::blueprint::components::{
    ColumnShare, ContainerKind, Eye3DKind, IncludedContent, PanelState, PlayState, QueryExpression, RowShare,
    TimelineName,
};
use rerun::external::re_sdk_types::external::uuid::Uuid;

/// The entities of the convergence panel: η, e_c and the errors against the reference (log10).
pub const CONVERGENCE: [&str; 4] = [
    "indicators/log10_eta",
    "indicators/log10_contact_indicator",
    "error/log10_traction",
    "error/log10_pointwise_traction",
];

/// Display names of the views, as the viewer shows them (and the tests look them up).
pub const STRUCTURE_VIEW: &str = "structure";
pub const CONVERGENCE_VIEW: &str = "log10 η, e_c, traction error (with --reference) per iteration";
pub const COUNTS_VIEW: &str = "contact statuses";
pub const FORCES_VIEW: &str = "interface resultants and boundary forces (N/mm; N in axisymmetry) over time";

/// A view of the layout: its class, name and entity-path filter.
struct ViewSpec {
    id: Uuid,
    class: &'static str,
    name: &'static str,
    contents: Vec<String>,
}

impl ViewSpec {
    fn new(class: &'static str, name: &'static str, contents: Vec<String>) -> Self {
        Self {
            id: Uuid::new_v4(),
            class,
            name,
            contents,
        }
    }

    fn path(&self) -> String {
        format!("view/{}", self.id)
    }
}

/// Sends the layout on `rec` and activates it (also as the application's default).
pub(crate) fn send(rec: &rerun::RecordingStream, frame: &Frame) -> Result<(), ReplayError> {
    let (bp_rec, storage) = rerun::RecordingStreamBuilder::new("glissade")
        .blueprint()
        .memory()
        .map_err(rerr)?;
    let blueprint_id = bp_rec
        .store_info()
        .ok_or_else(|| ReplayError::Rerun("the blueprint stream has no store info".into()))?
        .store_id;
    // The viewer reads blueprint data on this timeline.
    bp_rec.set_time_sequence("blueprint", 0);

    let quoted = |paths: &[&str]| paths.iter().map(|p| format!("+ /{p}")).collect::<Vec<_>>();
    let structure = ViewSpec::new(
        "3D",
        STRUCTURE_VIEW,
        quoted(&["subdomains/**", "interfaces/**", "legend/**"]),
    );
    let convergence = ViewSpec::new("TimeSeries", CONVERGENCE_VIEW, quoted(&CONVERGENCE));
    let counts = ViewSpec::new(
        "TimeSeries",
        COUNTS_VIEW,
        quoted(&["contact/**", "contact_over_time/**"]),
    );
    let forces = ViewSpec::new("TimeSeries", FORCES_VIEW, quoted(&["resultants/**", "boundary/**"]));
    for v in [&structure, &convergence, &counts, &forces] {
        bp_rec
            .log(
                format!("{}/ViewContents", v.path()),
                &bp::ViewContents::new(v.contents.iter().map(|q| QueryExpression(q.as_str().into()))),
            )
            .map_err(rerr)?;
        bp_rec
            .log(
                v.path(),
                &bp::ViewBlueprint::new(v.class)
                    .with_display_name(v.name)
                    .with_space_origin("/"),
            )
            .map_err(rerr)?;
    }
    let (position, target) = frame.eye();
    bp_rec
        .log(
            format!("{}/EyeControls3D", structure.path()),
            &bp::EyeControls3D::new()
                .with_kind(Eye3DKind::Orbital)
                .with_position(position)
                .with_look_target(target)
                .with_eye_up([0.0, 1.0, 0.0]),
        )
        .map_err(rerr)?;
    bp_rec
        .log(
            format!("{}/LineGrid3D", structure.path()),
            &bp::LineGrid3D::new().with_visible(false),
        )
        .map_err(rerr)?;

    let right = Uuid::new_v4();
    let root = Uuid::new_v4();
    let container = |id: Uuid| format!("container/{id}");
    bp_rec
        .log(
            container(right),
            &bp::ContainerBlueprint::new(ContainerKind::Vertical)
                .with_contents([convergence.path(), counts.path(), forces.path()].map(IncludedContent::from))
                .with_row_shares([3.0, 2.0, 2.0].map(RowShare::from)),
        )
        .map_err(rerr)?;
    bp_rec
        .log(
            container(root),
            &bp::ContainerBlueprint::new(ContainerKind::Horizontal)
                .with_contents([structure.path(), container(right)].map(IncludedContent::from))
                .with_col_shares([2.2, 1.0].map(ColumnShare::from)),
        )
        .map_err(rerr)?;
    bp_rec
        .log(
            "viewport",
            &bp::ViewportBlueprint::new()
                .with_root_container(root)
                .with_auto_layout(false)
                .with_auto_views(false),
        )
        .map_err(rerr)?;
    for panel in ["blueprint_panel", "selection_panel"] {
        bp_rec
            .log(panel, &bp::PanelBlueprint::new().with_state(PanelState::Collapsed))
            .map_err(rerr)?;
    }
    bp_rec
        .log(
            "time_panel",
            &bp::TimePanelBlueprint::new()
                .with_state(PanelState::Expanded)
                .with_timeline(TimelineName::from("iteration"))
                .with_play_state(PlayState::Following),
        )
        .map_err(rerr)?;
    bp_rec.flush_blocking().map_err(rerr)?;
    let msgs: Vec<LogMsg> = storage.take();
    rec.send_blueprint(
        msgs,
        BlueprintActivationCommand {
            blueprint_id,
            make_active: true,
            make_default: true,
        },
    );
    Ok(())
}
