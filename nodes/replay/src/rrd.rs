//! An .rrd read back with Rerun's own decoder: the layout its blueprint holds (views, the
//! structure view's eye, the time panel's timeline) and the colour range its legend states. The
//! tests check with it what a viewer will open; it reads only what this crate writes.

use crate::{rerr, ReplayError};
use rerun::external::re_log_encoding::DecoderApp;
use rerun::external::re_log_types::LogMsg;
use rerun::external::re_sdk_types::blueprint::archetypes as bp;
use rerun::external::re_sdk_types::blueprint::components::{
    AutoLayout, AutoViews, QueryExpression, TimelineName, ViewClass,
};
use rerun::external::re_sdk_types::components::{Name, Position3D, Vector3D};
use rerun::log::Chunk;
use rerun::{Component, ComponentIdentifier};
use std::collections::BTreeMap;
use std::path::Path;

/// A 3D eye: (position, look target, up).
pub type Eye = ([f32; 3], [f32; 3], [f32; 3]);

/// A view of the blueprint.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewInfo {
    /// Rerun's class identifier: `3D`, `2D`, `TimeSeries`, …
    pub class: String,
    pub name: String,
    /// The entity-path filter, one rule a line (`+ /subdomains/**`).
    pub contents: Vec<String>,
    /// The 3D eye set by the blueprint: (position, look target, up).
    pub eye: Option<Eye>,
}

/// What an .rrd holds for a viewer.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RrdContents {
    /// Blueprint stores sent (distinct ids), and activation commands for them.
    pub blueprints: usize,
    pub activations: usize,
    pub views: Vec<ViewInfo>,
    /// The viewport's automatic layout and views (false: the blueprint's panels only).
    pub auto_layout: Option<bool>,
    pub auto_views: Option<bool>,
    pub time_panel_timeline: Option<String>,
    /// Entity paths of the recording (not the blueprint), each once.
    pub entities: Vec<String>,
    /// `legend/range` of the final state, static or logged on the `time` timeline (not the
    /// iterations' of a live run): each of its fields (`lower`, `upper`, `min`, `max`,
    /// `lower_percentile`, `upper_percentile`).
    pub legend_range: BTreeMap<String, f64>,
}

/// The last row's values of component `C` at `id` in `chunk`, if it has any.
fn last<C: Component + Clone>(chunk: &Chunk, id: impl Into<ComponentIdentifier>) -> Option<Vec<C>> {
    chunk.iter_component::<C>(id.into()).last().map(|v| v.to_vec())
}

impl RrdContents {
    pub fn read(path: &Path) -> Result<Self, ReplayError> {
        let file = std::fs::File::open(path).map_err(|e| ReplayError::Content {
            path: path.display().to_string(),
            detail: e.to_string(),
        })?;
        let mut out = Self::default();
        let mut blueprint_ids = Vec::new();
        // Blueprint entities by path: view/<id>, view/<id>/ViewContents, view/<id>/EyeControls3D.
        let mut views: BTreeMap<String, ViewInfo> = BTreeMap::new();
        let mut eyes: BTreeMap<String, Eye> = BTreeMap::new();
        let mut contents: BTreeMap<String, Vec<String>> = BTreeMap::new();
        for msg in DecoderApp::decode_lazy(std::io::BufReader::new(file)) {
            let msg = msg.map_err(|e| ReplayError::Content {
                path: path.display().to_string(),
                detail: e.to_string(),
            })?;
            let (store, arrow) = match &msg {
                LogMsg::SetStoreInfo(info) => {
                    let id = &info.info.store_id;
                    if id.is_blueprint() && !blueprint_ids.contains(id) {
                        blueprint_ids.push(id.clone());
                    }
                    continue;
                }
                LogMsg::BlueprintActivationCommand(_) => {
                    out.activations += 1;
                    continue;
                }
                LogMsg::ArrowMsg(store, arrow) => (store, arrow),
            };
            let chunk = Chunk::from_arrow_msg(arrow).map_err(rerr)?;
            let entity = chunk.entity_path().to_string();
            let entity = entity.trim_start_matches('/').to_string();
            if !store.is_blueprint() {
                if !out.entities.contains(&entity) {
                    out.entities.push(entity.clone());
                }
                // The range that holds on the `time` timeline: static (a replay) or the final
                // state's (a live run: the only one logged with a time).
                let holds = chunk.is_static()
                    || chunk
                        .timelines()
                        .contains_key(&rerun::TimelineName::from_static_str("time"));
                if entity == "legend/range" && holds {
                    for d in chunk.component_descriptors() {
                        if let Some(v) =
                            last::<rerun::components::Scalar>(&chunk, d.component).and_then(|v| v.first().copied())
                        {
                            out.legend_range.insert(d.component.to_string(), v.0 .0);
                        }
                    }
                }
                continue;
            }
            if let Some(view) = entity.strip_prefix("view/") {
                match view.split_once('/') {
                    None => {
                        let class =
                            last::<ViewClass>(&chunk, bp::ViewBlueprint::descriptor_class_identifier().component);
                        let name = last::<Name>(&chunk, bp::ViewBlueprint::descriptor_display_name().component);
                        if let Some(class) = class.and_then(|c| c.first().cloned()) {
                            views.insert(
                                view.to_string(),
                                ViewInfo {
                                    class: class.0.to_string(),
                                    name: name
                                        .and_then(|n| n.first().cloned())
                                        .map(String::from)
                                        .unwrap_or_default(),
                                    contents: Vec::new(),
                                    eye: None,
                                },
                            );
                        }
                    }
                    Some((id, "ViewContents")) => {
                        if let Some(q) = last::<QueryExpression>(&chunk, bp::ViewContents::descriptor_query().component)
                        {
                            contents.insert(id.to_string(), q.iter().map(|q| q.0.to_string()).collect());
                        }
                    }
                    Some((id, "EyeControls3D")) => {
                        let p = last::<Position3D>(&chunk, bp::EyeControls3D::descriptor_position().component);
                        let t = last::<Position3D>(&chunk, bp::EyeControls3D::descriptor_look_target().component);
                        let u = last::<Vector3D>(&chunk, bp::EyeControls3D::descriptor_eye_up().component);
                        if let (Some(p), Some(t), Some(u)) = (p, t, u) {
                            if let (Some(p), Some(t), Some(u)) = (p.first(), t.first(), u.first()) {
                                eyes.insert(id.to_string(), (p.0 .0, t.0 .0, u.0 .0));
                            }
                        }
                    }
                    Some(_) => {}
                }
            } else if entity == "viewport" {
                if let Some(a) = last::<AutoLayout>(&chunk, bp::ViewportBlueprint::descriptor_auto_layout().component) {
                    out.auto_layout = a.first().map(|a| a.0 .0);
                }
                if let Some(a) = last::<AutoViews>(&chunk, bp::ViewportBlueprint::descriptor_auto_views().component) {
                    out.auto_views = a.first().map(|a| a.0 .0);
                }
            } else if entity == "time_panel" {
                if let Some(t) = last::<TimelineName>(&chunk, bp::TimePanelBlueprint::descriptor_timeline().component) {
                    out.time_panel_timeline = t.first().map(|t| t.0.to_string());
                }
            }
        }
        out.blueprints = blueprint_ids.len();
        for (id, mut v) in views {
            v.contents = contents.remove(&id).unwrap_or_default();
            v.eye = eyes.remove(&id);
            out.views.push(v);
        }
        Ok(out)
    }

    /// The view named `name`, if the blueprint has it.
    pub fn view(&self, name: &str) -> Option<&ViewInfo> {
        self.views.iter().find(|v| v.name == name)
    }
}
