//! What a recording writes before the run starts: its name, its settings (as recording
//! properties, `/__properties/settings`, and the first lines of the `summary` document),
//! with where the run goes besides the recording (offered to ROS 2 on a domain, `--ros2`;
//! written to a rosbag2 bag, `--bag DIR`), the static 3D scene, the start event and the
//! faults its settings inject (`--stall`, `--kill`), logged when the run reaches them.

use super::*;

/// Where a run goes besides its recording, one line each (for the summary), with its
/// recording property's key and value: ROS 2 (`ros2`: the domain it is offered on) and the
/// bag (`bag`: its folder).
pub(super) fn offered(opts: &RecordOptions) -> Vec<(&'static str, String, String)> {
    let mut out = Vec::new();
    if let Some(domain) = opts.ros2_domain {
        out.push((
            "ros2",
            format!("offered on domain {domain}"),
            format!("ROS 2: offered on domain {domain} (`ros2 node list` and `ros2 topic list` see its nodes and topics)"),
        ));
    }
    if let Some(dir) = &opts.bag {
        out.push((
            "bag",
            dir.display().to_string(),
            format!(
                "bag: what was offered to ROS 2, written as a rosbag2 bag (MCAP) in {}",
                dir.display()
            ),
        ));
    }
    out
}

/// The settings a recording keeps as its properties (`/__properties/settings`), by key: the
/// clock, the brain, the seed, the duration, the chapter's rates and depth, the graph (any
/// but the chapter's), the recording window and where the run goes besides the recording.
fn settings_values(
    cfg: &RunConfig,
    policy: &str,
    window: Option<RecordWindow>,
    opts: &RecordOptions,
) -> Vec<(&'static str, String)> {
    let text = |x: Option<String>| x.unwrap_or_else(|| "none (no chapter chain)".into());
    let mut settings = vec![
        ("clock", cfg.clock.to_string()),
        ("policy", policy.to_string()),
        ("seed", cfg.seed.to_string()),
        ("duration_s", cfg.duration.as_secs_f64().to_string()),
        ("sensor_hz", text(cfg.sensor_hz().map(|x| x.to_string()))),
        ("control_hz", text(cfg.control_hz().map(|x| x.to_string()))),
        ("actuator_hz", cfg.actuator_hz().to_string()),
        (
            "queue_depth",
            text(cfg.queue_depth().map(|x| x.to_string())),
        ),
    ];
    // The chapter's graph keeps the settings it had; any other names itself.
    if cfg.graph.name != "cartpole" {
        settings.push(("graph", cfg.graph.to_string()));
    }
    if let Some(w) = window {
        settings.push(("record_window", w.describe()));
    }
    settings.extend(offered(opts).into_iter().map(|(k, v, _)| (k, v)));
    settings
}

impl Recording {
    /// Log what is known before the run: the recording's name and settings (`opts`: where
    /// the run goes besides it, also said in the summary), the 3D scene, the summary in
    /// progress, the start event and the faults `cfg` injects (due when the run reaches them).
    pub(super) fn log_settings(&self, cfg: &RunConfig, policy: &str, opts: &RecordOptions) {
        let mut values = rerun::AnyValues::default();
        for (k, v) in settings_values(cfg, policy, self.window, opts) {
            values = values.with_component::<rerun::components::Text>(k, [v.as_str()]);
        }
        let offered_lines: Vec<String> = offered(opts).into_iter().map(|(_, _, l)| l).collect();
        self.extra_summary
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .extend(offered_lines.iter().cloned());
        let name = run_name(cfg, cfg.control_hz().map(hz_label));
        let properties = rerun::EntityPath::properties();
        let fixed = TimePoint::default();
        let mut buf = self.lock();
        buf.add(
            &properties.to_string(),
            &fixed,
            &rerun::RecordingInfo::update_fields().with_name(name),
        );
        buf.add(
            &properties
                .join(&rerun::EntityPath::from("settings"))
                .to_string(),
            &fixed,
            &values,
        );
        self.log_scene(&mut buf);
        let offered_md: String = offered_lines.iter().map(|l| format!("- {l}\n")).collect();
        buf.add(
            "summary",
            &fixed,
            &rerun::TextDocument::from_markdown(format!(
                "### Run in progress\n\n- {}\n- policy: {policy}\n{offered_md}\nThe summary appears here when the run ends.",
                settings_line(cfg)
            )),
        );
        buf.event(
            Nanos::ZERO,
            0,
            None,
            &format!(
                "start: {}",
                chapter_settings(cfg).unwrap_or_else(|| cfg.graph.to_string())
            ),
            rerun::components::TextLogLevel::INFO,
        );
        buf.when_document(false);
        // The faults the run injects (`--stall`, `--kill`), where they happen: a stalled
        // node's silence is otherwise recorded nowhere but in its not-alive count. Logged
        // when the run reaches them ([`Recording::log_due_events`]).
        let mut due: Vec<DueEvent> = cfg
            .faults
            .iter()
            .flat_map(|f| super::events::fault_events(f, Nanos::ZERO, false))
            .collect();
        super::events::in_time_order(&mut due, |e| e.0);
        *self.due_events.lock().unwrap_or_else(|e| e.into_inner()) = due.into();
        buf.send(&self.rec);
    }

    /// The static 3D scene: z up, the rail under the cart, the cart, the pole and the ±12°
    /// fall limits (which move with the cart).
    fn log_scene(&self, buf: &mut ChunkBuffer) {
        let fixed = TimePoint::default();
        buf.add("world", &fixed, &rerun::ViewCoordinates::RIGHT_HAND_Z_UP());
        let rail_z = -(CART_HALF_HEIGHT_M + RAIL_HALF_THICKNESS_M) as f32;
        buf.add(
            "world/rail",
            &fixed,
            &rerun::Boxes3D::from_centers_and_half_sizes(
                [(0.0, 0.0, rail_z)],
                [(
                    RAIL_HALF_LENGTH_M as f32,
                    0.015,
                    RAIL_HALF_THICKNESS_M as f32,
                )],
            )
            .with_colors([rgb(NEUTRAL_COLOR)]),
        );
        buf.add(
            "world/cart/body",
            &fixed,
            &rerun::Boxes3D::from_half_sizes([(0.1, 0.05, CART_HALF_HEIGHT_M as f32)])
                .with_colors([Color::from_rgb(60, 110, 200)])
                .with_fill_mode(rerun::components::FillMode::Solid),
        );
        buf.add(
            "world/cart/pole/body",
            &fixed,
            &rerun::Capsules3D::from_lengths_and_radii([1.0], [0.02])
                .with_colors([Color::from_rgb(230, 150, 50)]),
        );
        let reach = 1.1;
        let (sin, cos) = (THETA_LIMIT_RAD.sin() * reach, THETA_LIMIT_RAD.cos() * reach);
        let deg = THETA_LIMIT_RAD.to_degrees();
        let tips = [
            [-sin as f32, 0.0, cos as f32],
            [sin as f32, 0.0, cos as f32],
        ];
        buf.add(
            "world/cart/fall_limits",
            &fixed,
            &rerun::LineStrips3D::new(tips.map(|tip| [[0.0, 0.0, 0.0], tip]))
                .with_colors([rgb(LIMIT_COLOR)])
                .with_radii([0.004]),
        );
        buf.add(
            "world/cart/fall_limits/labels",
            &fixed,
            &rerun::Points3D::new(tips)
                .with_colors([rgb(LIMIT_COLOR)])
                .with_radii([0.01])
                .with_labels([format!("−{deg:.0}°"), format!("+{deg:.0}°")]),
        );
    }
}
