//! The plant and the figures: the cart-pole drawn, the pole angle against its limit, the
//! zero-order hold's staircase, the segment's counters and the sense→act latency
//! histogram.

use super::*;

pub(super) fn render_cartpole(v: &View, area: Rect, buf: &mut Buffer) {
    let x = v.cart_pos;
    let theta = v.pole_angle;
    // The verdict reads whole: in a narrow panel (80 columns) the panel's name gives way,
    // then the badge's padding ("BALANCED while the plant ran" is no plain BALANCED).
    let room = usize::from(area.width.saturating_sub(2));
    let verdict = match &v.verdict {
        // The hang's verdict in the first of its forms that fits the panel whole.
        Verdict::Hung {
            node,
            since_s,
            held_in,
        } => {
            let what = held_in.holding(node);
            let forms = vec![
                format!(" HUNG {what} since t={since_s:.2}s ✗ "),
                format!(" HUNG {what} t={since_s:.2}s "),
                format!(" HUNG: {node} since t={since_s:.2}s "),
                format!(" HUNG: {node} t={since_s:.2}s "),
            ];
            Span::from(first_that_fits(forms, room))
                .white()
                .on_red()
                .bold()
        }
        _ => badge(v),
    };
    let words = verdict.content.chars().count();
    let name = " cartpole ";
    let title = if name.len() + words <= room {
        Line::from(vec![name.into(), verdict])
    } else if words <= room {
        Line::from(verdict)
    } else {
        Line::from(Span::styled(
            verdict.content.trim().to_string(),
            verdict.style,
        ))
    };
    Canvas::default()
        .block(Block::bordered().title(title))
        .marker(Marker::Braille)
        .x_bounds([-2.6, 2.6])
        .y_bounds([-0.3, 1.2])
        .paint(move |ctx| {
            ctx.draw(&CanvasLine {
                x1: -2.4,
                y1: -0.05,
                x2: 2.4,
                y2: -0.05,
                color: Color::Gray,
            });
            // Fall limits: ±12° from the pivot.
            for sign in [-1.0, 1.0] {
                let a = sign * LIMIT_RAD;
                ctx.draw(&CanvasLine {
                    x1: x,
                    y1: 0.05,
                    x2: x + a.sin(),
                    y2: 0.05 + a.cos(),
                    color: Color::DarkGray,
                });
            }
            ctx.draw(&Rectangle {
                x: x - 0.2,
                y: -0.05,
                width: 0.4,
                height: 0.15,
                color: Color::Blue,
            });
            let color = if theta.abs() > LIMIT_RAD {
                Color::Red
            } else {
                Color::Yellow
            };
            ctx.draw(&CanvasLine {
                x1: x,
                y1: 0.05,
                x2: x + theta.sin(),
                y2: 0.05 + theta.cos(),
                color,
            });
        })
        .render(area, buf);
}

/// The pole angle against its fall limits over the charts' window; `open`: without a bottom
/// border, the force band's top one below serving for both (`chart_areas` in `view.rs`).
pub(super) fn render_angle_chart(v: &View, area: Rect, buf: &mut Buffer, open: bool) {
    let (t0, t1) = v.chart_s;
    let upper = [(t0, LIMIT_RAD), (t1, LIMIT_RAD)];
    let lower = [(t0, -LIMIT_RAD), (t1, -LIMIT_RAD)];
    let data: Vec<(f64, f64)> = v
        .angle_history
        .iter()
        .map(|&(t, a)| (t, a.clamp(-0.3, 0.3)))
        .collect();
    // A vertical mark at each change of settings: a new segment starts there.
    let marks: Vec<[(f64, f64); 2]> = v
        .segment
        .marks_s
        .iter()
        .filter(|&&t| t >= t0 && t <= t1)
        // A tick at the top edge, not a line across: a line read as a ±0.3 rad spike.
        .map(|&t| [(t, 0.26), (t, 0.3)])
        .collect();
    let ghost: Vec<(f64, f64)> = v
        .ghost_angle
        .iter()
        .map(|&(t, a)| (t, a.clamp(-0.3, 0.3)))
        .collect();
    let estimate: Vec<(f64, f64)> = v
        .angle_estimate
        .iter()
        .map(|&(t, a)| (t, a.clamp(-0.3, 0.3)))
        .collect();
    // The estimate over the truth in dashes, so that both show where they coincide (within
    // a braille dot at ±0.3 rad): `view/estimator.rs`.
    let dashes =
        super::estimator::dashes(&estimate, (t0, t1), super::estimator::plot_cols(area, 4));
    // The run before a reload first, so that this run's line is drawn over it.
    let mut datasets: Vec<Dataset<'_>> = ghost_dataset(&ghost).into_iter().collect();
    datasets.push(
        Dataset::default()
            .name("θ")
            .marker(Marker::Braille)
            .graph_type(GraphType::Line)
            .yellow()
            .data(&data),
    );
    datasets.extend(super::estimator::dash_datasets(&dashes, "θ̂"));
    datasets.extend([
        Dataset::default()
            .name("±12°")
            .marker(Marker::Braille)
            .graph_type(GraphType::Line)
            .red()
            .data(&upper),
        Dataset::default()
            .marker(Marker::Braille)
            .graph_type(GraphType::Line)
            .red()
            .data(&lower),
    ]);
    for (i, m) in marks.iter().enumerate() {
        let d = Dataset::default()
            .marker(Marker::Braille)
            .graph_type(GraphType::Line)
            .cyan()
            .data(m);
        datasets.push(if i == 0 { d.name("change") } else { d });
    }
    // The lines' key in the title (the chart's own legend hides when the chart is small):
    // the fall limits (±0.2095 rad, drawn between the axis's ±0.3 labels), the changes'
    // marks, then the window, each as long as the title has room.
    let room = usize::from(area.width.saturating_sub(2));
    // With an estimate, narrow panels (80 columns) name the truth θ to key θ̂ beside it.
    let narrow = !estimate.is_empty() && room < 60;
    let name = if narrow {
        " θ (rad) "
    } else {
        " pole angle (rad) "
    };
    // Paused, the run at the scrub cursor leads (the key follows where there is room).
    let (mut title, mut used) = match &v.readout {
        Some(r) => {
            let line = format!(" {} ", r.plant_line(room.saturating_sub(2)));
            let used = Span::raw(line.as_str()).width();
            (vec![Span::styled(line, Style::new().bold())], used)
        }
        None => (vec![Span::raw(name)], name.chars().count()),
    };
    let limits = format!("── ±{LIMIT_RAD:.2} fall ");
    let mut add = |title: &mut Vec<Span<'static>>, text: String, style: Style| {
        let n = text.chars().count() + 2;
        if used + n <= room {
            used += n;
            title.push(Span::raw("· "));
            title.push(Span::styled(text, style));
        }
    };
    add(&mut title, limits, Style::new().fg(Color::Red));
    if !estimate.is_empty() {
        let key = if narrow {
            "θ̂ est "
        } else {
            "θ̂ estimate "
        };
        add(&mut title, key.into(), Style::new().fg(Color::Magenta));
    }
    if !ghost.is_empty() {
        add(
            &mut title,
            "before reload ".into(),
            Style::new().fg(Color::DarkGray),
        );
    }
    if !marks.is_empty() {
        add(&mut title, "⡇ change ".into(), Style::new().fg(Color::Cyan));
    }
    add(&mut title, format!("{} ", v.chart_label), Style::new());
    Chart::new(datasets)
        .block(angle_block(v, area, open).title(Line::from(title)))
        .x_axis(super::axis::time_axis(t0, t1, area))
        .y_axis(
            Axis::default()
                .bounds([-0.3, 0.3])
                .labels(["-0.3", "0", "0.3"]),
        )
        .render(area, buf);
}

/// The pole-angle chart's block; `open`: without its bottom border. With an estimator in the
/// graph, its bottom border (where it has one) gives θ̂'s error and lag and says where the
/// estimator's chart is (`view/estimator.rs`).
fn angle_block(v: &View, area: Rect, open: bool) -> Block<'static> {
    if open {
        use ratatui::widgets::Borders;
        return Block::new().borders(Borders::TOP | Borders::LEFT | Borders::RIGHT);
    }
    let room = usize::from(area.width.saturating_sub(2));
    let foot = v
        .estimator
        .as_ref()
        .filter(|_| area.height >= 3)
        .and_then(|e| super::estimator::angle_foot(e, room));
    match foot {
        Some(foot) => Block::bordered().title_bottom(foot),
        None => Block::bordered(),
    }
}

/// The run before a reload ([`View::ghost_angle`], [`View::ghost_force`]) as a dim line,
/// `None` without one.
fn ghost_dataset(points: &[(f64, f64)]) -> Option<Dataset<'_>> {
    (!points.is_empty()).then(|| {
        Dataset::default()
            .name("before")
            .marker(Marker::Braille)
            .graph_type(GraphType::Line)
            .dark_gray()
            .data(points)
    })
}

/// The zero-order hold, live: the force the policy published (dots, at its ticks) and the
/// force the actuator applied (a staircase: each step's force held until the next).
/// `joined`: right under the angle chart, its top border that chart's bottom one (`├ ┤`).
pub(super) fn render_hold_chart(v: &View, area: Rect, buf: &mut Buffer, joined: bool) {
    let (t0, t1) = v.chart_s;
    let limit = ratelab::plant::GEAR_N;
    let clamp = |pts: &[(f64, f64)]| -> Vec<(f64, f64)> {
        pts.iter()
            .map(|&(t, f)| (t, f.clamp(-limit, limit)))
            .collect()
    };
    let (applied, published) = (clamp(&v.applied_force), clamp(&v.published_force));
    let ghost = clamp(&v.ghost_force);
    let mut datasets: Vec<Dataset<'_>> = ghost_dataset(&ghost).into_iter().collect();
    datasets.extend([
        Dataset::default()
            .name("applied")
            .marker(Marker::Braille)
            .graph_type(GraphType::Line)
            .green()
            .data(&applied),
        Dataset::default()
            .name("published")
            .marker(Marker::Braille)
            .graph_type(GraphType::Scatter)
            .magenta()
            .data(&published),
    ]);
    // Three labels need three rows of plot (80×24 has them: [`super::HOLD_ROWS`]). A band
    // of two rows cannot put a label on 0 N: the braille grid draws 0 N in the upper row (at
    // its lowest dot), so its rows are labelled by what they hold, ≥ 0 above and < 0 below,
    // not by ±10 at their ends, which read as if 0 N were 10 N.
    let labels: &[&str] = if area.height >= 5 {
        &["-10", "0", "10"]
    } else {
        &["<0", "≥0"]
    };
    // Paused, the hold at the scrub cursor (the force, its command's age) and the selected
    // topic's counters; else the band's key.
    let room = usize::from(area.width.saturating_sub(2));
    let mut title = match &v.readout {
        Some(r) => vec![Span::styled(
            format!(" {} ", r.hold_line(room.saturating_sub(2))),
            Style::new().bold(),
        )],
        None => vec![
            " force (N): ".into(),
            "published".magenta(),
            " · ".into(),
            "applied".green(),
            " — the hold ".into(),
        ],
    };
    let used: usize = title.iter().map(Span::width).sum();
    let key_fits = v.readout.is_none() || used + "· before reload ".chars().count() <= room;
    if !ghost.is_empty() && area.width >= 60 && key_fits {
        title.extend(["· ".into(), "before reload ".dark_gray()]);
    }
    let title = Line::from(title);
    let block = if joined {
        use ratatui::symbols::{border, line};
        Block::bordered().border_set(border::Set {
            top_left: line::VERTICAL_RIGHT,
            top_right: line::VERTICAL_LEFT,
            ..border::PLAIN
        })
    } else {
        Block::bordered()
    };
    Chart::new(datasets)
        .block(block.title(title))
        .hidden_legend_constraints((Constraint::Length(0), Constraint::Length(0)))
        .x_axis(super::axis::time_axis(t0, t1, area))
        .y_axis(
            Axis::default()
                .bounds([-limit, limit])
                .labels(labels.iter().copied()),
        )
        .render(area, buf);
}

/// The segment line: what the arrows count over (the window), then each topic's totals since
/// the last change of settings (or the start), saying since when, with the change when the
/// width allows.
pub(super) fn render_segment(v: &View, area: Rect, buf: &mut Buffer) {
    let seg = &v.segment;
    // `short`: 0 says it in words, 1 shortens "dropped", 2 also writes stale reads as `N↺`
    // (the arrows' symbol), so that no number is cut at 80 columns.
    let topics = |short: u8| -> Vec<Span<'static>> {
        let mut spans: Vec<Span> = Vec::new();
        // A topic nobody reads has no drops to total (the arrow says "no subscriber").
        for (i, t) in v
            .topics
            .iter()
            .filter(|t| t.subscriber.is_some())
            .enumerate()
        {
            if i > 0 {
                spans.push(" · ".dim());
            }
            spans.push(format!("{} ", t.name).into());
            let dropped = if short > 0 {
                format!("{} drop", t.segment_dropped)
            } else {
                format!("{} dropped", t.segment_dropped)
            };
            spans.push(if t.segment_dropped > 0 {
                dropped.yellow().bold()
            } else {
                dropped.into()
            });
            if t.segment_stale_reads > 0 {
                spans.push(if short > 1 {
                    format!(" {}↺", t.segment_stale_reads).magenta()
                } else {
                    format!(", {} stale", t.segment_stale_reads).magenta()
                });
            }
            if t.segment_lost > 0 {
                spans.push(if short > 1 {
                    format!(" {} lost", t.segment_lost).red()
                } else {
                    format!(", {} lost", t.segment_lost).red()
                });
            }
            // Lifespan's count: unread messages that grew too old (never read, as a drop).
            if t.segment_expired > 0 {
                spans.push(if short > 1 {
                    format!(" {} expired", t.segment_expired).yellow()
                } else {
                    format!(", {} expired", t.segment_expired).yellow()
                });
            }
        }
        spans
    };
    let since = seg.since();
    let mut heads: Vec<String> = Vec::new();
    if let Some(cause) = &seg.cause {
        heads.push(format!(" totals since the change at {since} ({cause}): "));
        heads.push(format!(" totals since the change at {since}: "));
    }
    heads.push(format!(" totals since {since}: "));
    // From the most to the least said, the first that fits.
    let mut candidates: Vec<Vec<Span>> = Vec::new();
    for head in &heads {
        let mut line = vec![
            " arrows: ".dim(),
            seg.window_label().bold(),
            " │".dim(),
            Span::from(head.clone()).dim(),
        ];
        line.extend(topics(0));
        candidates.push(line);
    }
    for short in [0, 1, 2] {
        let mut line = vec![
            " ".into(),
            seg.window_label().bold(),
            " │".dim(),
            Span::from(format!(" since {since}: ")).dim(),
        ];
        line.extend(topics(short));
        candidates.push(line);
    }
    // Narrower: the totals without their "since" (the latency panel's title says it), but
    // still called totals (after "last 5 s" alone they read as the window's).
    let mut line = vec![
        " ".into(),
        seg.window_label().bold(),
        " │".dim(),
        " totals: ".dim(),
    ];
    line.extend(topics(2));
    candidates.push(line);
    // The narrowest: the totals alone (the arrows' window is in the latency panel's foot).
    let mut line = vec![" totals: ".dim()];
    line.extend(topics(2));
    candidates.push(line);
    let width = |l: &Vec<Span>| l.iter().map(|s| s.content.chars().count()).sum::<usize>();
    let last = candidates.len() - 1;
    let line = candidates
        .iter()
        .position(|l| width(l) <= area.width as usize)
        .map_or_else(|| candidates[last].clone(), |i| candidates[i].clone());
    Paragraph::new(Line::from(line)).render(area, buf);
}

/// `n=81 (+19 no cmd) │ p50 20.0 │ p99 220.0 │ max 220.0 ms `: a latency panel's figures.
/// Steps that applied no command have no latency: said beside n, not silently left out.
/// With no sample there is no latency to give, not one of 0 ms: `none (20 steps, no
/// command applied) `, as the summary says `none`.
fn latency_figures(count: u64, no_command: u64, p50_ms: f64, p99_ms: f64, max_ms: f64) -> String {
    if count == 0 {
        return match no_command {
            0 => "none (no command applied) ".to_string(),
            n => format!("none ({n} steps, no command applied) "),
        };
    }
    let no_cmd = if no_command > 0 {
        format!(" (+{no_command} no cmd)")
    } else {
        String::new()
    };
    format!("n={count}{no_cmd} │ p50 {p50_ms:.1} │ p99 {p99_ms:.1} │ max {max_ms:.1} ms ")
}

pub(super) fn render_latency(v: &View, area: Rect, buf: &mut Buffer) {
    let l = &v.latency;
    let since = match v.segment.joined_s {
        Some(t) => format!("{t:.2} s (joined)"),
        None => v.segment.since(),
    };
    let figures = latency_figures(l.count, l.no_command, l.p50_ms, l.p99_ms, l.max_ms);
    // "sense→act" and "since …" when the width allows them; the figures whole always.
    let title = first_that_fits(
        [
            format!(" sense→act latency since {since}: {figures}"),
            format!(" latency since {since}: {figures}"),
            format!(" latency {figures}"),
        ],
        usize::from(area.width).saturating_sub(2),
    );
    let w = &l.window;
    let window = Line::from(vec![
        " ".into(),
        v.segment.latency_window_label().bold(),
        format!(
            ": {}",
            latency_figures(w.count, w.no_command, w.p50_ms, w.p99_ms, w.max_ms)
        )
        .into(),
    ]);
    let inner_w = area.width.saturating_sub(2);
    let n = l.buckets.len().max(1) as u16;
    let block = Block::bordered().title(title).title_bottom(window);
    if l.ghost.len() == l.buckets.len() && !l.ghost.is_empty() {
        render_latency_beside_ghost(l, block, inner_w / n, area, buf);
        return;
    }
    let bars: Vec<Bar> = l
        .buckets
        .iter()
        .map(|(label, n)| Bar::default().value(*n).label(Line::from(label.clone())))
        .collect();
    let bar_w = (inner_w / n).saturating_sub(1).clamp(1, 12);
    BarChart::default()
        .block(block)
        .data(BarGroup::default().bars(&bars))
        .bar_width(bar_w)
        .bar_gap(1)
        .bar_style(Style::new().fg(Color::Cyan))
        .value_style(Style::new().fg(Color::Black).bg(Color::Cyan))
        .render(area, buf);
}

/// After a reload: each bucket as a pair, the run before's count over the same span of
/// run time (dim, left) beside this run's (cyan, right), `per_bucket` columns a pair.
fn render_latency_beside_ghost(
    l: &LatencyView,
    block: Block<'_>,
    per_bucket: u16,
    area: Rect,
    buf: &mut Buffer,
) {
    // Two bars and the gap between groups in each bucket's columns.
    let bar_w = (per_bucket.saturating_sub(1) / 2).clamp(1, 6);
    let groups: Vec<BarGroup> = l
        .buckets
        .iter()
        .zip(&l.ghost)
        .map(|((label, n), before)| {
            BarGroup::default().label(Line::from(label.clone())).bars(&[
                // Its height only: this run's count is the one written.
                Bar::default()
                    .value(*before)
                    .text_value(String::new())
                    .style(Style::new().fg(Color::DarkGray)),
                Bar::default().value(*n),
            ])
        })
        .collect();
    let mut chart = BarChart::default()
        .block(block.title_bottom(Line::from(" dim: before reload ".dark_gray()).right_aligned()))
        .bar_width(bar_w)
        .bar_gap(0)
        .group_gap(per_bucket.saturating_sub(2 * bar_w).max(1))
        .bar_style(Style::new().fg(Color::Cyan))
        .value_style(Style::new().fg(Color::Black).bg(Color::Cyan));
    for g in groups {
        chart = chart.data(g);
    }
    chart.render(area, buf);
}
