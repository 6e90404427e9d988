//! A mission: the position items a vehicle flies in order, in local NED about a home.
//!
//! Two file formats read into the same [`Mission`]:
//!
//! * **QGroundControl `.plan`** (JSON; QGC's "Plan File Format"): the `mission.items`
//!   list of `SimpleItem`s, each a MAVLink `MAV_CMD` with seven `params`
//!   (`[p1, p2, p3, p4, lat, lon, alt]`) in a MAVLink `frame`, and
//!   `mission.plannedHomePosition` = `[lat, lon, alt AMSL]`, the origin of the local frame.
//!   Flown: `NAV_TAKEOFF` (22), `NAV_WAYPOINT` (16: p1 hold [s], p2 acceptance radius [m],
//!   0 = the default), `NAV_LOITER_TIME` (19: p1 hold [s]), `NAV_LAND` (21: the landing
//!   point; its descent is the autopilot's) and `DO_CHANGE_SPEED` (178: p2 the speed of the
//!   following legs [m/s], p1 0/1 = air/ground speed, −1 = no change). Frames
//!   `GLOBAL_RELATIVE_ALT` (3, 6) and `GLOBAL` (0, 5: altitude AMSL). Anything else —
//!   another command, a `ComplexItem`, a terrain frame, `autoContinue` false, an item after
//!   a landing — is refused before anything flies, naming the item:
//!   `mission.items[4]: command 20 (RTL) is not supported`.
//! * **TOML**, NED waypoints directly (see [`Mission::from_toml`]).
//!
//! Latitude/longitude become North/East by [`super::geo::LocalProjection`] (PX4's
//! projection) about the home; Down is minus the altitude above home. Yaw and pass radii are
//! not used (the autopilot holds the heading; legs end at rest when there is a hold).

use serde::{Deserialize, Serialize};
use serde_json::Value;

use super::geo::{GeoPoint, LocalProjection};
use crate::config::{in_range, non_negative, ConfigError};

/// Leg speed when a file names none (PX4's `MPC_XY_CRUISE` default) [m/s].
pub const DEFAULT_SPEED: f64 = 5.0;
/// Acceptance radius when an item names none (PX4's multicopter `NAV_ACC_RAD`) [m].
pub const DEFAULT_ACCEPTANCE_RADIUS: f64 = 2.0;
/// Fastest leg speed accepted [m/s].
pub const MAX_SPEED: f64 = 20.0;
/// Longest hold accepted [s].
pub const MAX_HOLD: f64 = 3600.0;
/// Farthest item from home accepted [m].
pub const MAX_RANGE: f64 = 50_000.0;

/// What an item asks the vehicle to do at its position.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ItemKind {
    /// Climb to the item's altitude (above the point it starts from).
    Takeoff,
    /// Fly to the item and hold there for its hold time.
    Waypoint,
    /// Fly to the landing point at the current altitude; the descent is the autopilot's.
    Land,
}

impl ItemKind {
    /// Short name for reports (`takeoff`, `waypoint`, `land`).
    pub fn name(self) -> &'static str {
        match self {
            ItemKind::Takeoff => "takeoff",
            ItemKind::Waypoint => "waypoint",
            ItemKind::Land => "land",
        }
    }
}

/// One position item of a mission.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MissionItem {
    /// What the item is.
    pub kind: ItemKind,
    /// Target position, NED about the mission's home [m].
    pub position: [f64; 3],
    /// Time to stay at the item once it is reached [s].
    pub hold: f64,
    /// Horizontal distance within which the item counts as reached [m].
    pub acceptance_radius: f64,
    /// Speed of the leg that ends at this item [m/s].
    pub speed: f64,
    /// Index of the item in the file's own item list (for messages and reports).
    pub source: usize,
}

/// A mission: position items in flying order (module docs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Mission {
    /// Name for reports.
    pub name: String,
    /// Geodetic origin of the NED frame, when the file gives one.
    pub home: Option<GeoPoint>,
    /// The items, in order.
    pub items: Vec<MissionItem>,
}

/// The TOML mission file (see [`Mission::from_toml`]).
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct TomlMission {
    #[serde(default)]
    name: Option<String>,
    #[serde(default)]
    speed: Option<f64>,
    #[serde(default)]
    acceptance_radius: Option<f64>,
    #[serde(default)]
    hold: Option<f64>,
    #[serde(default)]
    home: Option<[f64; 3]>,
    #[serde(default)]
    waypoint: Vec<TomlWaypoint>,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct TomlWaypoint {
    n: f64,
    e: f64,
    d: f64,
    #[serde(default)]
    kind: Option<ItemKind>,
    #[serde(default)]
    hold: Option<f64>,
    #[serde(default)]
    speed: Option<f64>,
    #[serde(default)]
    acceptance_radius: Option<f64>,
}

/// Well-known `MAV_CMD` names for messages about commands swingrt does not fly.
fn command_name(cmd: i64) -> &'static str {
    match cmd {
        16 => "WAYPOINT",
        17 => "LOITER_UNLIM",
        18 => "LOITER_TURNS",
        19 => "LOITER_TIME",
        20 => "RTL",
        21 => "LAND",
        22 => "TAKEOFF",
        30 => "CONTINUE_AND_CHANGE_ALT",
        31 => "LOITER_TO_ALT",
        80 => "ROI",
        82 => "SPLINE_WAYPOINT",
        84 => "VTOL_TAKEOFF",
        85 => "VTOL_LAND",
        92 => "GUIDED_ENABLE",
        93 => "DELAY",
        112 => "CONDITION_DELAY",
        114 => "CONDITION_DISTANCE",
        115 => "CONDITION_YAW",
        177 => "DO_JUMP",
        178 => "DO_CHANGE_SPEED",
        179 => "DO_SET_HOME",
        183 => "DO_SET_SERVO",
        189 => "DO_LAND_START",
        200 => "DO_CONTROL_VIDEO",
        201 => "DO_SET_ROI",
        203 => "DO_DIGICAM_CONTROL",
        205 => "DO_MOUNT_CONTROL",
        206 => "DO_SET_CAM_TRIGG_DIST",
        211 => "DO_GRIPPER",
        212 => "DO_AUTOTUNE_ENABLE",
        530 => "SET_CAMERA_MODE",
        2000 => "IMAGE_START_CAPTURE",
        2001 => "IMAGE_STOP_CAPTURE",
        2500 => "VIDEO_START_CAPTURE",
        2501 => "VIDEO_STOP_CAPTURE",
        3000 => "VTOL_TRANSITION",
        42600 => "DO_WINCH",
        _ => "unknown",
    }
}

fn frame_name(frame: i64) -> &'static str {
    match frame {
        0 => "GLOBAL",
        1 => "LOCAL_NED",
        2 => "MISSION",
        3 => "GLOBAL_RELATIVE_ALT",
        4 => "LOCAL_ENU",
        5 => "GLOBAL_INT",
        6 => "GLOBAL_RELATIVE_ALT_INT",
        10 => "GLOBAL_TERRAIN_ALT",
        11 => "GLOBAL_TERRAIN_ALT_INT",
        _ => "unknown",
    }
}

impl Mission {
    /// Read a mission from a file's text, by its extension (`plan` or `toml`).
    pub fn from_text(text: &str, extension: &str) -> Result<Self, ConfigError> {
        match extension.to_ascii_lowercase().as_str() {
            "plan" | "json" => Self::from_qgc_plan(text),
            "toml" => Self::from_toml(text),
            other => Err(ConfigError::new(
                "mission",
                format!(
                    "unknown mission file type .{other} (use a QGroundControl .plan or a .toml)"
                ),
            )),
        }
    }

    /// Read a TOML mission of NED waypoints:
    ///
    /// ```toml
    /// name = "delivery"            # optional
    /// speed = 5.0                  # default leg speed [m/s] (5)
    /// acceptance_radius = 1.0      # default [m] (2)
    /// hold = 0.0                   # default hold [s] (0)
    /// home = [47.3977, 8.5456, 488.0]   # optional geodetic origin: lat, lon [deg], alt AMSL [m]
    /// [[waypoint]]
    /// n = 0.0                      # North [m]
    /// e = 40.0                     # East [m]
    /// d = -10.0                    # Down [m] (negative is up)
    /// kind = "waypoint"            # or "takeoff", "land"
    /// hold = 5.0                   # [s]
    /// speed = 5.0                  # of the leg to this waypoint [m/s]
    /// acceptance_radius = 0.5      # [m]
    /// ```
    pub fn from_toml(text: &str) -> Result<Self, ConfigError> {
        let table = crate::config::parse_toml(text).map_err(|e| e.within("mission"))?;
        let doc: TomlMission = crate::config::from_toml_value(toml::Value::Table(table))
            .map_err(|e| e.within("mission"))?;
        let at = |f: &str| format!("mission.{f}");
        let speed = doc.speed.unwrap_or(DEFAULT_SPEED);
        check_speed(&at("speed"), speed)?;
        let radius = doc.acceptance_radius.unwrap_or(DEFAULT_ACCEPTANCE_RADIUS);
        check_radius(&at("acceptance_radius"), radius)?;
        let hold = doc.hold.unwrap_or(0.0);
        check_hold(&at("hold"), hold)?;
        let home = match doc.home {
            Some([lat, lon, alt]) => {
                let g = GeoPoint { lat, lon, alt };
                g.validate().map_err(|e| e.within("mission.home"))?;
                Some(g)
            }
            None => None,
        };
        let mut items = Vec::with_capacity(doc.waypoint.len());
        for (i, w) in doc.waypoint.iter().enumerate() {
            let field = |f: &str| format!("mission.waypoint[{i}].{f}");
            let pos = [w.n, w.e, w.d];
            for (k, name) in ["n", "e", "d"].iter().enumerate() {
                in_range(&field(name), pos[k], -MAX_RANGE, MAX_RANGE)?;
            }
            let item = MissionItem {
                kind: w.kind.unwrap_or(ItemKind::Waypoint),
                position: pos,
                hold: w.hold.unwrap_or(hold),
                acceptance_radius: w.acceptance_radius.unwrap_or(radius),
                speed: w.speed.unwrap_or(speed),
                source: i,
            };
            check_hold(&field("hold"), item.hold)?;
            check_radius(&field("acceptance_radius"), item.acceptance_radius)?;
            check_speed(&field("speed"), item.speed)?;
            items.push(item);
        }
        let m = Mission {
            name: doc.name.unwrap_or_else(|| "mission".into()),
            home,
            items,
        };
        m.check_order(|i| format!("mission.waypoint[{i}]"))?;
        Ok(m)
    }

    /// Read a QGroundControl `.plan` (module docs); every refusal names the item.
    pub fn from_qgc_plan(text: &str) -> Result<Self, ConfigError> {
        let doc: Value = serde_json::from_str(text).map_err(|e| {
            ConfigError::new(
                "mission",
                format!("not a QGroundControl plan (invalid JSON: {e})"),
            )
        })?;
        if doc.get("fileType").and_then(Value::as_str) != Some("Plan") {
            return Err(ConfigError::new(
                "fileType",
                "must be \"Plan\" (a QGroundControl plan file)",
            ));
        }
        let mission = doc
            .get("mission")
            .filter(|m| m.is_object())
            .ok_or_else(|| ConfigError::new("mission", "missing (the plan has no mission)"))?;
        let home = match mission.get("plannedHomePosition").and_then(Value::as_array) {
            Some(a) if a.len() == 3 => {
                let num = |i: usize| a[i].as_f64().unwrap_or(f64::NAN);
                let g = GeoPoint {
                    lat: num(0),
                    lon: num(1),
                    alt: num(2),
                };
                g.validate()
                    .map_err(|e| e.within("mission.plannedHomePosition"))?;
                g
            }
            _ => {
                return Err(ConfigError::new(
                    "mission.plannedHomePosition",
                    "missing or not [lat, lon, alt]: the home is the origin of the local frame",
                ))
            }
        };
        let raw = mission
            .get("items")
            .and_then(Value::as_array)
            .ok_or_else(|| ConfigError::new("mission.items", "missing or not a list"))?;
        let proj = LocalProjection::new(home.lat, home.lon);
        let mut items: Vec<MissionItem> = Vec::new();
        let mut speed = DEFAULT_SPEED;
        let mut landed: Option<usize> = None;
        for (i, it) in raw.iter().enumerate() {
            let field = format!("mission.items[{i}]");
            let err = |msg: String| ConfigError::new(field.clone(), msg);
            let kind = it.get("type").and_then(Value::as_str).unwrap_or("");
            if kind != "SimpleItem" {
                let what = it
                    .get("complexItemType")
                    .and_then(Value::as_str)
                    .map(|c| format!("{kind} ({c})"))
                    .unwrap_or_else(|| format!("item type {kind:?}"));
                return Err(err(format!("{what} is not supported")));
            }
            let cmd = it
                .get("command")
                .and_then(Value::as_i64)
                .ok_or_else(|| err("command: missing or not an integer".into()))?;
            if let Some(j) = landed {
                return Err(err(format!(
                    "command {cmd} ({}) after the landing at mission.items[{j}] is not supported",
                    command_name(cmd)
                )));
            }
            if it.get("autoContinue").and_then(Value::as_bool) == Some(false) {
                return Err(err(
                    "autoContinue false (wait for the operator) is not supported".into(),
                ));
            }
            let params: Vec<f64> = match it.get("params").and_then(Value::as_array) {
                Some(p) if p.len() == 7 => {
                    p.iter().map(|v| v.as_f64().unwrap_or(f64::NAN)).collect()
                }
                _ => return Err(err("params: must be a list of 7 values".into())),
            };
            let frame = it.get("frame").and_then(Value::as_i64).unwrap_or(-1);
            let position = |last: [f64; 3]| -> Result<[f64; 3], ConfigError> {
                let (lat, lon, alt) = (params[4], params[5], params[6]);
                let (n, e) = if lat.is_finite() && lon.is_finite() && (lat != 0.0 || lon != 0.0) {
                    GeoPoint {
                        lat,
                        lon,
                        alt: home.alt,
                    }
                    .validate()
                    .map_err(|e| e.within(&field))?;
                    proj.project(lat, lon)
                } else {
                    (last[0], last[1])
                };
                let d = match frame {
                    3 | 6 => -alt,
                    0 | 5 => -(alt - home.alt),
                    f => {
                        return Err(err(format!(
                            "frame {f} ({}) is not supported (use relative or AMSL altitude)",
                            frame_name(f)
                        )))
                    }
                };
                let pos = [n, e, if alt.is_finite() { d } else { last[2] }];
                for (k, v) in pos.iter().enumerate() {
                    if !(v.is_finite() && v.abs() <= MAX_RANGE) {
                        return Err(err(format!(
                            "{} is {v} m from home (at most {MAX_RANGE} m)",
                            ["north", "east", "down"][k]
                        )));
                    }
                }
                Ok(pos)
            };
            let last = items.last().map(|x| x.position).unwrap_or([0.0, 0.0, 0.0]);
            let radius_of = |p: f64| -> Result<f64, ConfigError> {
                let r = if p.is_finite() && p > 0.0 {
                    p
                } else {
                    DEFAULT_ACCEPTANCE_RADIUS
                };
                check_radius(&format!("{field}.params[1]"), r)?;
                Ok(r)
            };
            let hold_of = |p: f64| -> Result<f64, ConfigError> {
                let h = if p.is_finite() { p } else { 0.0 };
                check_hold(&format!("{field}.params[0]"), h)?;
                Ok(h)
            };
            match cmd {
                16 | 19 => {
                    let radius = if cmd == 16 {
                        radius_of(params[1])?
                    } else {
                        DEFAULT_ACCEPTANCE_RADIUS
                    };
                    items.push(MissionItem {
                        kind: ItemKind::Waypoint,
                        position: position(last)?,
                        hold: hold_of(params[0])?,
                        acceptance_radius: radius,
                        speed,
                        source: i,
                    });
                }
                22 => {
                    let mut pos = position(last)?;
                    if items.is_empty() && !(params[4].is_finite() && params[5].is_finite()) {
                        pos[0] = 0.0;
                        pos[1] = 0.0;
                    }
                    items.push(MissionItem {
                        kind: ItemKind::Takeoff,
                        position: pos,
                        hold: 0.0,
                        acceptance_radius: DEFAULT_ACCEPTANCE_RADIUS,
                        speed,
                        source: i,
                    });
                }
                21 => {
                    let mut pos = position(last)?;
                    pos[2] = last[2];
                    items.push(MissionItem {
                        kind: ItemKind::Land,
                        position: pos,
                        hold: 0.0,
                        acceptance_radius: DEFAULT_ACCEPTANCE_RADIUS,
                        speed,
                        source: i,
                    });
                    landed = Some(i);
                }
                178 => {
                    let (kind, value) = (params[0], params[1]);
                    if kind.is_finite() && kind != 0.0 && kind != 1.0 {
                        return Err(err(format!(
                            "DO_CHANGE_SPEED of speed type {kind} (climb or descent speed) is not \
                             supported"
                        )));
                    }
                    if value.is_finite() && value > 0.0 {
                        check_speed(&format!("{field}.params[1]"), value)?;
                        speed = value;
                    }
                }
                other => {
                    return Err(err(format!(
                        "command {other} ({}) is not supported",
                        command_name(other)
                    )))
                }
            }
        }
        let name = doc
            .get("name")
            .and_then(Value::as_str)
            .unwrap_or("plan")
            .to_string();
        let m = Mission {
            name,
            home: Some(home),
            items,
        };
        m.check_order(|i| format!("mission.items[{i}]"))?;
        Ok(m)
    }

    /// Check the item sequence as a whole: at least one item, a takeoff only first, a
    /// landing only last. `field` names item `source` in the file's terms.
    fn check_order(&self, field: impl Fn(usize) -> String) -> Result<(), ConfigError> {
        if self.items.is_empty() {
            return Err(ConfigError::new(
                "mission",
                "has no position item (takeoff, waypoint or land) to fly",
            ));
        }
        for (k, it) in self.items.iter().enumerate() {
            if it.kind == ItemKind::Takeoff && k != 0 {
                return Err(ConfigError::new(
                    field(it.source),
                    "a takeoff is supported only as the first item",
                ));
            }
            if it.kind == ItemKind::Land && k + 1 != self.items.len() {
                return Err(ConfigError::new(
                    field(it.source),
                    "a landing is supported only as the last item",
                ));
            }
        }
        Ok(())
    }

    /// Check every item's numbers and the order of the items; errors name
    /// `mission.items[k]` (for missions built in code or read from JSON).
    pub fn validate(&self) -> Result<(), ConfigError> {
        if let Some(h) = &self.home {
            h.validate().map_err(|e| e.within("mission.home"))?;
        }
        for (k, it) in self.items.iter().enumerate() {
            let field = |f: &str| format!("mission.items[{k}].{f}");
            for (i, name) in ["n", "e", "d"].iter().enumerate() {
                in_range(
                    &field(&format!("position.{name}")),
                    it.position[i],
                    -MAX_RANGE,
                    MAX_RANGE,
                )?;
            }
            check_hold(&field("hold"), it.hold)?;
            check_radius(&field("acceptance_radius"), it.acceptance_radius)?;
            check_speed(&field("speed"), it.speed)?;
        }
        self.check_order(|i| format!("mission.items[{i}]"))
    }

    /// Where the vehicle starts: above the first item (the takeoff point at its altitude,
    /// or hovering over home at the first waypoint's altitude), NED [m].
    pub fn start(&self) -> [f64; 3] {
        let first = &self.items[0];
        match first.kind {
            ItemKind::Takeoff => first.position,
            _ => [0.0, 0.0, first.position[2]],
        }
    }

    /// The projection about the home, when the mission has one.
    pub fn projection(&self) -> Option<LocalProjection> {
        self.home.map(|h| LocalProjection::new(h.lat, h.lon))
    }

    /// The mission with every position shifted by `offset` (NED) [m].
    pub fn shifted(&self, offset: [f64; 3]) -> Self {
        let mut m = self.clone();
        for it in &mut m.items {
            for k in 0..3 {
                it.position[k] += offset[k];
            }
        }
        m
    }

    /// The same mission as TOML text (for reports and reproducibility).
    pub fn to_toml(&self) -> String {
        let mut s = format!("name = {:?}\n", self.name);
        if let Some(h) = self.home {
            s += &format!("home = [{}, {}, {}]\n", h.lat, h.lon, h.alt);
        }
        for it in &self.items {
            s += &format!(
                "\n[[waypoint]]\nkind = {:?}\nn = {}\ne = {}\nd = {}\nhold = {}\nspeed = {}\nacceptance_radius = {}\n",
                it.kind.name(),
                it.position[0],
                it.position[1],
                it.position[2],
                it.hold,
                it.speed,
                it.acceptance_radius
            );
        }
        s
    }
}

fn check_speed(field: &str, v: f64) -> Result<(), ConfigError> {
    in_range(field, v, 0.1, MAX_SPEED)
}

fn check_radius(field: &str, v: f64) -> Result<(), ConfigError> {
    in_range(field, v, 0.05, 100.0)
}

fn check_hold(field: &str, v: f64) -> Result<(), ConfigError> {
    non_negative(field, v)?;
    in_range(field, v, 0.0, MAX_HOLD)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plan(items: &str) -> String {
        format!(
            r#"{{"fileType": "Plan", "version": 1, "groundStation": "QGroundControl",
            "geoFence": {{"circles": [], "polygons": [], "version": 2}},
            "rallyPoints": {{"points": [], "version": 2}},
            "mission": {{"cruiseSpeed": 15, "firmwareType": 12, "hoverSpeed": 5,
              "plannedHomePosition": [47.397742, 8.545594, 488.0], "vehicleType": 2,
              "version": 2, "items": [{items}]}}}}"#
        )
    }

    fn item(cmd: i64, frame: i64, params: &str) -> String {
        format!(
            r#"{{"type": "SimpleItem", "autoContinue": true, "command": {cmd}, "doJumpId": 1,
            "frame": {frame}, "params": [{params}], "AltitudeMode": 1}}"#
        )
    }

    #[test]
    fn qgc_plan_items_become_ned_about_home() {
        let home = LocalProjection::new(47.397742, 8.545594);
        let (lat, lon) = home.reproject(40.0, -20.0);
        let text = plan(
            &[
                item(22, 3, "0, 0, 0, null, 47.397742, 8.545594, 12"),
                item(178, 2, "1, 3.5, -1, 0, 0, 0, 0"),
                item(16, 3, &format!("5, 0.5, 0, null, {lat}, {lon}, 15")),
                item(16, 0, &format!("0, 0, 0, null, {lat}, {lon}, 500")),
                item(21, 3, "0, 0, 0, null, 47.397742, 8.545594, 0"),
            ]
            .join(","),
        );
        let m = Mission::from_qgc_plan(&text).unwrap();
        assert_eq!(m.items.len(), 4);
        let kinds: Vec<_> = m.items.iter().map(|i| i.kind).collect();
        assert_eq!(
            kinds,
            [
                ItemKind::Takeoff,
                ItemKind::Waypoint,
                ItemKind::Waypoint,
                ItemKind::Land
            ]
        );
        assert_eq!(m.items[0].position, [0.0, 0.0, -12.0]);
        let wp = &m.items[1];
        assert!((wp.position[0] - 40.0).abs() < 1e-6 && (wp.position[1] + 20.0).abs() < 1e-6);
        assert_eq!(
            (wp.position[2], wp.hold, wp.acceptance_radius, wp.speed),
            (-15.0, 5.0, 0.5, 3.5)
        );
        // AMSL altitude 500 m over a home at 488 m; radius 0 means the default.
        assert!((m.items[2].position[2] + 12.0).abs() < 1e-9);
        assert_eq!(m.items[2].acceptance_radius, DEFAULT_ACCEPTANCE_RADIUS);
        // The landing point keeps the altitude it is flown at.
        assert_eq!(m.items[3].position[2], -12.0);
        assert_eq!(m.items[3].source, 4);
        assert_eq!(m.start(), [0.0, 0.0, -12.0]);
    }

    #[test]
    fn unsupported_items_are_refused_by_name() {
        let text = plan(
            &[
                item(22, 3, "0, 0, 0, null, 47.397742, 8.545594, 12"),
                item(16, 3, "0, 0, 0, null, 47.3978, 8.5456, 12"),
                item(16, 3, "0, 0, 0, null, 47.3979, 8.5456, 12"),
                item(16, 3, "0, 0, 0, null, 47.3979, 8.5457, 12"),
                item(20, 2, "0, 0, 0, 0, 0, 0, 0"),
            ]
            .join(","),
        );
        let e = Mission::from_qgc_plan(&text).unwrap_err();
        assert_eq!(
            e.to_string(),
            "mission.items[4]: command 20 (RTL) is not supported"
        );
        let survey = r#"{"type": "ComplexItem", "complexItemType": "survey"}"#;
        let e = Mission::from_qgc_plan(&plan(survey)).unwrap_err();
        assert_eq!(
            e.to_string(),
            "mission.items[0]: ComplexItem (survey) is not supported"
        );
        let e =
            Mission::from_qgc_plan(&plan(&item(16, 10, "0, 0, 0, 0, 47.3, 8.5, 10"))).unwrap_err();
        assert!(
            e.to_string().contains("frame 10 (GLOBAL_TERRAIN_ALT)"),
            "{e}"
        );
        let e = Mission::from_qgc_plan(&plan(&item(178, 2, "2, 1, 0, 0, 0, 0, 0"))).unwrap_err();
        assert!(e.to_string().contains("speed type 2"), "{e}");
        let e =
            Mission::from_qgc_plan(&plan(&item(16, 3, "-1, 0, 0, 0, 47.3, 8.5, 10"))).unwrap_err();
        assert_eq!(e.field, "mission.items[0].params[0]");
        let after_land = [
            item(21, 3, "0, 0, 0, null, 47.397742, 8.545594, 0"),
            item(16, 3, "0, 0, 0, null, 47.3979, 8.5456, 12"),
        ]
        .join(",");
        let e = Mission::from_qgc_plan(&plan(&after_land)).unwrap_err();
        assert!(
            e.to_string()
                .starts_with("mission.items[1]: command 16 (WAYPOINT) after the landing"),
            "{e}"
        );
        assert!(Mission::from_qgc_plan("{")
            .unwrap_err()
            .to_string()
            .contains("invalid JSON"));
        assert!(Mission::from_qgc_plan(&plan(""))
            .unwrap_err()
            .to_string()
            .contains("no position item"));
    }

    #[test]
    fn toml_missions_take_defaults_and_name_bad_fields() {
        let m = Mission::from_toml(
            "speed = 4.0\nhold = 2.0\n[[waypoint]]\nn = 0\ne = 0\nd = -10\nkind = \"takeoff\"\n\
             [[waypoint]]\nn = 30\ne = 0\nd = -10\nhold = 5\nacceptance_radius = 0.5\n",
        )
        .unwrap();
        assert_eq!(m.items[1].speed, 4.0);
        assert_eq!((m.items[1].hold, m.items[1].acceptance_radius), (5.0, 0.5));
        assert_eq!(m.items[0].hold, 2.0);
        let e = Mission::from_toml("[[waypoint]]\nn = 0\ne = 0\nd = -10\nspeed = 0\n").unwrap_err();
        assert_eq!(e.field, "mission.waypoint[0].speed");
        let e = Mission::from_toml("[[waypoint]]\nn = 0\ne = 0\nd = -10\nholdd = 1\n").unwrap_err();
        assert!(e.to_string().contains("holdd"), "{e}");
        let e = Mission::from_toml(
            "[[waypoint]]\nn = 0\ne = 0\nd = -10\n[[waypoint]]\nn = 0\ne = 1\n\
                                    d = -10\nkind = \"takeoff\"\n",
        )
        .unwrap_err();
        assert_eq!(e.field, "mission.waypoint[1]");
        let back = Mission::from_toml(&m.to_toml()).unwrap();
        assert_eq!(back.items, m.items);
    }
}
