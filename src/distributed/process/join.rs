//! A process joining its launch: its options checked against the graph file
//! ([`check_options`]), its session opened to the launcher's router with its identity, the
//! launcher's setup taken ([`Joined`]), and the waits on the launcher's messages and
//! matching subscribers that joining and running share.

use super::*;

/// Check `opts` before anything connects: its graph file parses and places
/// `opts.process`, the credentials are this graph's and this placement's and hold the
/// process's identity, the endpoints are well formed. Returns the graph file's graph.
///
/// # Errors
/// [`DistError::Usage`], one line naming what is wrong.
pub(super) fn check_options(opts: &ProcessOptions) -> Result<GraphSpec, DistError> {
    let file_spec = crate::graph_file(&opts.graph_bytes, &opts.graph_origin)?;
    let placement = file_spec.placement();
    if !placement.iter().any(|(p, _)| *p == opts.process) {
        let names: Vec<&str> = placement.iter().map(|(p, _)| p.as_str()).collect();
        return Err(DistError::Usage(format!(
            "graph '{}' has no process '{}' (its processes: {})",
            file_spec.name,
            opts.process,
            ratelab_core::text::listed(names)
        )));
    }
    if opts.connect.is_empty() {
        return Err(DistError::Usage(
            "--connect tls/HOST:PORT is required: the launcher's endpoint".into(),
        ));
    }
    let role = Role::Process(opts.process.clone());
    crate::credentials_fit(&opts.credentials, &file_spec)?;
    opts.credentials.identity(&role)?;
    for ep in &opts.connect {
        check_endpoint("--connect", ep, false)?;
    }
    for ep in &opts.listen {
        check_endpoint("--listen", ep, true)?;
    }
    Ok(file_spec)
}

/// A process joined to its launcher: its session, the launcher's control messages and the
/// run's settings from the welcome.
pub(super) struct Joined {
    pub(super) session: zenoh::Session,
    pub(super) keys: Keys,
    /// The launcher's control messages to this process.
    pub(super) ctl_rx: Receiver<ToProcess>,
    /// The launcher's liveliness token: gone once withdrawn for good
    /// ([`crate::liveliness`]).
    pub(super) launcher_gone: TokenWatch,
    /// Where this process speaks to the launcher (its own key).
    pub(super) up: zenoh::pubsub::Publisher<'static>,
    /// The run's settings.
    pub(super) setup: Box<wire::Setup>,
    pub(super) _ctl_sub: zenoh::pubsub::Subscriber<()>,
    pub(super) _launcher_watch: zenoh::pubsub::Subscriber<()>,
}

impl Joined {
    /// Open the session to `opts.connect`, wait for the launcher, join with the graph
    /// file's hash and wait for the welcome (asking again for [`BUSY_RETRY`] while a
    /// process of this name still runs).
    ///
    /// # Errors
    /// [`DistError`]: the session cannot open, the launcher runs another graph, the join
    /// is refused, the real clock's processes are on hosts whose clocks differ, `stop`.
    pub(super) fn join(
        opts: &ProcessOptions,
        file_spec: &GraphSpec,
        stop: &StopFlag,
    ) -> Result<Joined, DistError> {
        let role = Role::Process(opts.process.clone());
        let access = Access {
            credentials: &opts.credentials,
            role: &role,
            spec: Some(file_spec),
        };
        // A client of the launcher's router, its one link ([`crate::open_client`]), or,
        // listening, a peer that the launch's other processes link to directly.
        let session = match opts.listen.is_empty() {
            true => open_client(&opts.connect, access)?,
            false => crate::open_linked_peer(&opts.listen, &opts.connect, access)?,
        };
        let keys = Keys::new(&file_spec.name);
        let (ctl_tx, ctl_rx) = crossbeam_channel::bounded::<ToProcess>(4096);
        let _ctl_sub = session
            .declare_subscriber(keys.control(&opts.process))
            .callback(move |s| {
                if let Ok(m) = wire::decode_json::<ToProcess>(&s.payload().to_bytes()) {
                    let _ = ctl_tx.try_send(m);
                }
            })
            .wait()?;
        // The launcher's token: withdrawn for good, the run is over for us too (Zenoh may
        // withdraw it for a moment as this peer's links change: [`crate::liveliness`]).
        let launcher_gone = TokenWatch::new();
        let _launcher_watch = {
            let gone = launcher_gone.clone();
            session
                .liveliness()
                .declare_subscriber(keys.launcher_token())
                .history(true)
                .callback(move |s| gone.note(s.kind()))
                .wait()?
        };
        // Control messages and samples are never dropped under congestion (Zenoh's default
        // drops): a lost grant or report would stall the run.
        let block = zenoh::qos::CongestionControl::Block;
        let up = session
            .declare_publisher(keys.up_from(&opts.process))
            .congestion_control(block)
            .wait()?;
        // Not matched at once: a launcher of another graph at the endpoint means this process
        // was given another graph file (the keys carry the graph's name, so the hash exchanged
        // at join never comes): say so now rather than after the wait.
        let soon = Instant::now() + Duration::from_secs(2);
        while Instant::now() < soon && !up.matching_status().wait().is_ok_and(|m| m.matching()) {
            std::thread::sleep(Duration::from_millis(20));
        }
        if !up.matching_status().wait().is_ok_and(|m| m.matching()) {
            let seen = launchers_seen(&session);
            if !seen.is_empty() && !seen.iter().any(|g| g == keys.graph()) {
                return Err(DistError::Usage(format!(
                    "the launcher at {} runs graph '{}', not '{}': was this process given another graph file?",
                    opts.connect.join(", "),
                    seen.join("', '"),
                    keys.graph()
                )));
            }
        }
        // As long as the launcher waits for its processes to be ready: a launch of
        // hundreds starting on a few cores is answered late.
        let patience = crate::ready_wait(opts.credentials.processes.len());
        wait_matching(&up, stop, (None, patience), "the launcher")?;
        let send = |m: &ToLauncher| up.put(wire::encode_json(m)).wait();
        let join = ToLauncher::Join {
            process: opts.process.clone(),
            graph_sha256: crate::graph_hash(&opts.graph_bytes),
            pid: std::process::id(),
        };
        send(&join)?;
        let first_join = std::time::Instant::now();
        // The answer to the join. The control key is the process name's, so a process of that
        // name already running (this one is a second copy, or rejoins too early) gets its run's
        // messages there too: those are not for this one, which waits on.
        let setup = loop {
            match recv(&ctl_rx, stop, &launcher_gone)? {
                ToProcess::Welcome {
                    setup,
                    launcher_mono_ns,
                } => {
                    let apart_s = wire::mono_now_ns().abs_diff(launcher_mono_ns) as f64 / 1e9;
                    if setup.clock == crate::ClockKind::Real && apart_s > 2.0 {
                        return Err(DistError::Usage(format!(
                            "the real clock needs every process on the launcher's host (the monotonic clocks differ by {apart_s:.0} s); across hosts use --clock virtual"
                        )));
                    }
                    break setup;
                }
                // Started again the moment the one before was killed: the launcher has not
                // yet seen its liveliness token go. Ask again, for a while.
                ToProcess::Reject { busy: true, .. } if first_join.elapsed() < BUSY_RETRY => {
                    // Soon: every message of the gap is a reading lost to the policy.
                    std::thread::sleep(Duration::from_millis(100));
                    send(&join)?;
                }
                ToProcess::Reject { reason, .. } => return Err(DistError::Usage(reason)),
                _ => {}
            }
        };
        Ok(Joined {
            session,
            keys,
            ctl_rx,
            launcher_gone,
            up,
            setup,
            _ctl_sub,
            _launcher_watch,
        })
    }
}

/// The next control message: waits as long as the launcher lives (its liveliness token),
/// so processes started by hand may join minutes apart; an error on a stop or when the
/// launcher is gone.
pub(super) fn recv(
    rx: &Receiver<ToProcess>,
    stop: &StopFlag,
    gone: &TokenWatch,
) -> Result<ToProcess, DistError> {
    loop {
        match rx.recv_timeout(Duration::from_millis(50)) {
            Ok(m) => return Ok(m),
            Err(RecvTimeoutError::Disconnected) => {
                return Err(DistError::Peer("the launcher's channel closed".into()))
            }
            Err(RecvTimeoutError::Timeout) if gone.is_gone() => {
                return Err(DistError::Peer("the launcher went away".into()))
            }
            Err(RecvTimeoutError::Timeout) if stop.is_stopped() => {
                return Err(DistError::Peer("interrupted".into()))
            }
            Err(RecvTimeoutError::Timeout) => {}
        }
    }
}

/// The next control message for this process once welcomed: a busy refusal is for another
/// process of its name asking to join (the control key is the name's: a second copy, or this
/// one's own join that crossed its welcome), never for this one; a receipt of a report is
/// for the copy before this one.
pub(super) fn recv_own(
    rx: &Receiver<ToProcess>,
    stop: &StopFlag,
    gone: &TokenWatch,
) -> Result<ToProcess, DistError> {
    loop {
        match recv(rx, stop, gone)? {
            ToProcess::Reject { busy: true, .. } | ToProcess::ReportTaken => {}
            m => return Ok(m),
        }
    }
}

/// Wait until `p` has a matching subscriber (`who`, for the error): while the launcher
/// lives when `gone` watches it, else for `patience`.
pub(super) fn wait_matching(
    p: &zenoh::pubsub::Publisher<'_>,
    stop: &StopFlag,
    (gone, patience): (Option<&TokenWatch>, Duration),
    who: &str,
) -> Result<(), DistError> {
    poll_until(
        stop,
        gone,
        gone.is_none().then(|| Instant::now() + patience),
        Duration::from_millis(10),
        || match p.matching_status().wait().is_ok_and(|m| m.matching()) {
            true => Ok(()),
            false => Err(()),
        },
        |()| {
            format!(
                "{who} did not subscribe to {} within {} s",
                p.key_expr(),
                patience.as_secs()
            )
        },
    )
}

/// Wait until what this process publishes across is heard: linked directly (`linked`: the
/// launch's other processes, by name) to each other process ([`wait_linked`]) and each of
/// them subscribed to all it hears ([`wait_subscribed`]), and each of `publishers` matched
/// by its subscriber (the launcher, or linked directly a subscribing process) while the
/// launcher is there (not `gone`). The subscribing process subscribes before it says it is
/// ready, and the run starts once all are.
///
/// # Errors
/// As [`wait_linked`], [`wait_subscribed`] and [`wait_matching`].
pub(super) fn wait_heard(
    session: &zenoh::Session,
    keys: &Keys,
    (publishers, linked): (&super::bridge::Publishers, Option<&[String]>),
    stop: &StopFlag,
    launcher_gone: &TokenWatch,
) -> Result<(), DistError> {
    let while_there = (Some(launcher_gone), REPLY_TIMEOUT);
    if let Some(others) = linked {
        wait_linked(session, others.len(), stop, while_there)?;
        wait_subscribed(session, keys, others, stop, while_there)?;
    }
    let subscriber = match linked {
        Some(_) => "the subscribing process",
        None => "the launcher",
    };
    for (_, p) in publishers {
        wait_matching(p, stop, while_there, subscriber)?;
    }
    Ok(())
}

/// Linked directly: wait until each of `others` (process names) has subscribed to all it
/// hears from this process, its samples and its tick reports, as its node tokens show
/// (`@node/<process>/<node>`, [`Keys::node_token`]): a process declares them after its
/// subscribers, and a peer's declarations reach this one in the order it made them. A
/// publisher's matching says only that some subscriber is there, and the first tick report
/// sent before another process's subscriber is known here would be lost to it (a peer
/// sends only where it knows a subscriber), its lockstep stalled. For `patience` at most,
/// and not after the launcher is gone when `gone` watches it.
///
/// # Errors
/// [`DistError::Peer`] on `stop`, the launcher gone, or a process not heard of after
/// `patience` (naming them), [`DistError::Zenoh`] when the tokens cannot be watched.
pub(super) fn wait_subscribed(
    session: &zenoh::Session,
    keys: &Keys,
    others: &[String],
    stop: &StopFlag,
    (gone, patience): (Option<&TokenWatch>, Duration),
) -> Result<(), DistError> {
    let heard: Arc<Mutex<std::collections::BTreeSet<String>>> = Arc::default();
    let _watch = {
        let (heard, keys) = (heard.clone(), keys.clone());
        session
            .liveliness()
            .declare_subscriber(keys.node_token("*", "*"))
            .history(true)
            .callback(move |s| {
                if s.kind() == zenoh::sample::SampleKind::Put {
                    if let Some(p) = keys.process_of_node_token(s.key_expr().as_str()) {
                        heard
                            .lock()
                            .unwrap_or_else(|e| e.into_inner())
                            .insert(p.to_string());
                    }
                }
            })
            .wait()?
    };
    poll_until(
        stop,
        gone,
        gone.is_none().then(|| Instant::now() + patience),
        Duration::from_millis(2),
        || {
            let heard = heard.lock().unwrap_or_else(|e| e.into_inner());
            let missing: Vec<&str> = others
                .iter()
                .filter(|p| !heard.contains(p.as_str()))
                .map(String::as_str)
                .collect();
            match missing.is_empty() {
                true => Ok(()),
                false => Err(missing),
            }
        },
        |missing| {
            format!(
                "not subscribed within {} s, linked directly: {} (a process announces its nodes once it has subscribed)",
                patience.as_secs(),
                ratelab_core::text::listed(missing)
            )
        },
    )
}

/// Wait until this peer's `session` is linked to `others` peers (the launch's other
/// processes, in a launch linked directly: [`crate::open_linked_peer`]), for `patience` at
/// most, and not after the launcher is gone when `gone` watches it. Each link is opened as
/// the launcher's router tells each process of the others (Zenoh's gossip): on one host,
/// within milliseconds of the last process's start.
///
/// # Errors
/// [`DistError::Peer`] on `stop`, the launcher gone, or fewer links after `patience`.
pub(super) fn wait_linked(
    session: &zenoh::Session,
    others: usize,
    stop: &StopFlag,
    (gone, patience): (Option<&TokenWatch>, Duration),
) -> Result<(), DistError> {
    poll_until(
        stop,
        gone,
        Some(Instant::now() + patience),
        Duration::from_millis(2),
        || {
            let linked = session.info().peers_zid().wait().count();
            match linked >= others {
                true => Ok(()),
                false => Err(linked),
            }
        },
        |linked| {
            format!(
                "linked directly to {linked} of the launch's {others} other processes within {} s (each listens on its --listen, and the launcher's router tells each of the others)",
                patience.as_secs()
            )
        },
    )
}

/// Poll `ready` every `every` until it holds (`Ok`): the loop of this module's waits for
/// what the process hears of its peers ([`wait_matching`], [`wait_subscribed`],
/// [`wait_linked`]).
/// Its `Err` is what is still missing, said by `timed_out` once `deadline` (if any) passes.
///
/// # Errors
/// [`DistError::Peer`]: "interrupted" on `stop`; "the launcher went away" once `gone`
/// (watching the launcher's liveliness token) is stopped; `timed_out`'s line after
/// `deadline`. `stop` and `gone` are checked only while `ready` does not hold, so a wait
/// already met succeeds.
fn poll_until<T>(
    stop: &StopFlag,
    gone: Option<&TokenWatch>,
    deadline: Option<Instant>,
    every: Duration,
    mut ready: impl FnMut() -> Result<(), T>,
    timed_out: impl FnOnce(T) -> String,
) -> Result<(), DistError> {
    loop {
        let missing = match ready() {
            Ok(()) => return Ok(()),
            Err(missing) => missing,
        };
        if stop.is_stopped() {
            return Err(DistError::Peer("interrupted".into()));
        }
        if gone.is_some_and(TokenWatch::is_gone) {
            return Err(DistError::Peer("the launcher went away".into()));
        }
        if deadline.is_some_and(|d| Instant::now() >= d) {
            return Err(DistError::Peer(timed_out(missing)));
        }
        std::thread::sleep(every);
    }
}

/// The graphs (their names as in their keys) whose launchers this session sees, by their
/// liveliness tokens (at most 16; asked for up to 1 s).
pub(super) fn launchers_seen(session: &zenoh::Session) -> Vec<String> {
    crate::live_tokens(session, "ratelab/*/@launcher", Duration::from_secs(1), 16)
        .iter()
        .filter_map(|key| {
            key.strip_prefix("ratelab/")
                .and_then(|k| k.strip_suffix("/@launcher"))
                .map(str::to_string)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::liveliness::WITHDRAWN_FOR;

    const NOW: Duration = Duration::from_millis(1);

    fn said(r: Result<(), DistError>) -> String {
        r.unwrap_err().to_string()
    }

    #[test]
    fn a_wait_ends_when_ready_and_says_what_is_missing_at_its_deadline() {
        let stop = StopFlag::new();
        let mut polls = 0;
        fn polls_left(n: &mut u32) -> Result<(), u32> {
            *n = n.saturating_sub(1);
            if *n == 0 {
                Ok(())
            } else {
                Err(*n)
            }
        }
        let mut left = 3;
        poll_until(
            &stop,
            None,
            None,
            NOW,
            || polls_left(&mut left),
            |_| unreachable!(),
        )
        .unwrap();
        assert_eq!(left, 0);
        let e = said(poll_until(
            &stop,
            None,
            Some(Instant::now()),
            NOW,
            || {
                polls += 1;
                Err(polls)
            },
            |n| format!("still {n} missing"),
        ));
        assert!(e.contains("still 1 missing"), "{e}");
    }

    #[test]
    fn a_wait_ends_on_a_stop_or_the_launcher_gone_but_not_once_met() {
        let (stop, gone) = (StopFlag::new(), TokenWatch::new());
        // Withdrawn for good: longer ago than the grace.
        let long_ago = wire::mono_now_ns().saturating_sub(2 * WITHDRAWN_FOR.as_nanos() as u64);
        gone.note_at(zenoh::sample::SampleKind::Delete, long_ago);
        // A wait watching the launcher, without a deadline, until `ready` holds.
        let watching = |ready: Result<(), ()>| {
            poll_until(&stop, Some(&gone), None, NOW, || ready, |()| unreachable!())
        };
        let e = said(watching(Err(())));
        assert!(e.contains("the launcher went away"), "{e}");
        watching(Ok(())).unwrap();
        stop.stop();
        let e = said(watching(Err(())));
        assert!(e.contains("interrupted"), "{e}");
    }

    /// A wait watching `gone`, without a deadline, ready at its `ready_at`-th poll;
    /// `each(n)` runs at the n-th poll first.
    fn ready_at_poll(
        gone: &TokenWatch,
        ready_at: u32,
        mut each: impl FnMut(u32),
    ) -> Result<(), DistError> {
        let mut polls = 0;
        let ready = || {
            polls += 1;
            each(polls);
            if polls == ready_at {
                Ok(())
            } else {
                Err(())
            }
        };
        poll_until(
            &StopFlag::new(),
            Some(gone),
            None,
            NOW,
            ready,
            |()| unreachable!(),
        )
    }

    /// Zenoh withdrew the launcher's token for a moment as the processes linked to each
    /// other (declared again 5 ms later): the wait goes on.
    #[test]
    fn a_wait_rides_out_the_launcher_s_token_withdrawn_for_a_moment() {
        let gone = TokenWatch::new();
        gone.note(zenoh::sample::SampleKind::Delete);
        ready_at_poll(&gone, 10, |n| {
            if n == 3 {
                gone.note(zenoh::sample::SampleKind::Put);
            }
        })
        .unwrap();
        assert!(!gone.is_gone_at(u64::MAX), "declared again: never gone");
    }

    #[test]
    fn a_wait_without_a_deadline_goes_on_until_ready_while_the_launcher_lives() {
        let started = Instant::now();
        ready_at_poll(&TokenWatch::new(), 20, |_| {}).unwrap();
        assert!(started.elapsed() >= 19 * NOW);
    }
}
