//! The service's handlers: a worker's work request, failure and outcome, a
//! controller's command, the replies to queries, and the publishing helpers.

use super::*;

/// A worker reported a trial it could not (or would not) run.
pub(super) fn on_failure(st: &mut State, f: &TrialFailure) -> Result<(), ServiceError> {
    let t = (f.iteration, f.trial);
    match st.sched.answered(t, &f.worker, f.dispatch, Instant::now()) {
        Answer::Held if f.refused => {
            st.count_failure(format!("given back: {}", f.reason));
            // Beyond its limits, or it is stopping: not the trial's failure.
            tracing::info!(worker = %f.worker, iteration = f.iteration, trial = f.trial, reason = %f.reason, "a worker gave a trial back");
            st.counters.redispatched += 1;
            st.sched.enqueue(t, Instant::now());
        }
        Answer::Held => {
            tracing::warn!(worker = %f.worker, iteration = f.iteration, trial = f.trial, reason = %f.reason, "a worker could not run a trial");
            st.failed(t, &f.worker, &f.reason)?;
        }
        other => st.refuse(&f.worker, &format!("failure report: {}", other.reason())),
    }
    Ok(())
}

/// Whether `req`'s worker may run this run's trials: the run's fingerprint
/// is pinned by the first worker that asks (journaled before any of its
/// outcomes), and from then on only workers of that fingerprint get trials.
/// A resumed run that meets only workers of other fingerprints ends.
pub(super) fn fingerprint_fits(
    st: &mut State,
    req: &WorkRequest,
) -> Result<Option<String>, ServiceError> {
    let ours = match st.facts.fingerprint {
        Some(f) => f,
        None => {
            st.facts.fingerprint = Some(req.fingerprint);
            tracing::info!(worker = %req.worker, fingerprint = %show_fingerprint(req.fingerprint), version = %req.version, "the run's worker fingerprint is pinned");
            st.send(Cmd::Fingerprint {
                fingerprint: req.fingerprint,
                version: req.version.clone(),
                worker: req.worker.clone(),
            })?;
            req.fingerprint
        }
    };
    if req.fingerprint == ours {
        st.matched = true;
        st.mismatched.remove(&req.worker);
        return Ok(None);
    }
    let why = format!(
        "fingerprint: this run's trials are run by workers of fingerprint {}; this worker's is {} (naofarm {}): its bits might differ",
        show_fingerprint(ours),
        show_fingerprint(req.fingerprint),
        req.version
    );
    st.refuse(&req.worker, "work request of another worker fingerprint");
    if st
        .mismatched
        .insert(req.worker.clone(), req.fingerprint)
        .is_none()
    {
        tracing::warn!(worker = %req.worker, "{why}");
    }
    no_worker_fits(st, true)?;
    Ok(Some(why))
}

/// Why `req`'s worker may not run this run's trials for want of the run's
/// trial program (it did not register one of that name), if so.
fn program_misfit(exp: &protocol::Experiment, req: &WorkRequest) -> Option<String> {
    match (&exp.program, &req.program) {
        (Some(ours), Some(theirs)) if ours == theirs => None,
        (Some(ours), _) => Some(format!(
            "program: this run's trials run the program `{ours}`, which this worker has not registered"
        )),
        (None, Some(theirs)) => Some(format!(
            "program: this run runs no program, the worker offered `{theirs}`"
        )),
        (None, None) => None,
    }
}

/// A run whose every live worker asked with another fingerprint than the
/// run's ends at once: its history could not go on with the same bits. A
/// resumed run ends so before any worker of its fingerprint served it; a
/// served run when a worker just asked with another (its program was
/// rebuilt under it), never only because a worker left.
pub(super) fn no_worker_fits(st: &State, asked: bool) -> Result<(), ServiceError> {
    let Some(ours) = st.facts.fingerprint else {
        return Ok(());
    };
    let all_other =
        !st.mismatched.is_empty() && st.live.iter().all(|w| st.mismatched.contains_key(w));
    // A resumed run no worker of its fingerprint served yet; or, when a
    // worker just asked with another fingerprint, a run whose every live
    // worker now has another (a program rebuilt under its workers).
    let ends = if st.matched {
        asked && !st.live.is_empty()
    } else {
        st.journaled_fingerprint
    };
    if all_other && ends {
        let theirs = st
            .mismatched
            .iter()
            .map(|(w, f)| format!("{} on worker {w}", show_fingerprint(*f)))
            .collect::<Vec<_>>()
            .join(", ");
        return Err(ServiceError::NoMatchingWorker {
            id: st.facts.id.clone(),
            ours: show_fingerprint(ours),
            theirs,
        });
    }
    Ok(())
}

/// A worker asks for trials: grant up to its free slots, in one reply that only it receives.
pub(super) async fn on_work(st: &mut State, q: &zenoh::query::Query) -> Result<(), ServiceError> {
    st.counters.work_requests += 1;
    let Some(payload) = q.payload() else {
        st.refuse("a query without payload", "work request: empty");
        reply_err(q, "a work request needs a WorkRequest payload").await;
        return Ok(());
    };
    let req = match WorkRequest::decode(&payload.to_bytes()) {
        Ok(r) => r,
        Err(e) => {
            st.refuse("an undecodable message", &format!("work request: {e}"));
            reply_err(q, &e.to_string()).await;
            return Ok(());
        }
    };
    let state = st.state();
    let mut note = None;
    let mut trials = Vec::new();
    let misfit = if state == RunState::Running {
        // Before the fingerprint: a worker without the program pins nothing.
        match program_misfit(&st.facts.experiment, &req) {
            Some(why) => {
                st.refuse(&req.worker, "work request without the run's program");
                Some(why)
            }
            None => fingerprint_fits(st, &req)?,
        }
    } else {
        None
    };
    let exp = &st.facts.experiment;
    let refused = misfit.is_some();
    if let Some(why) = misfit {
        note = Some(why);
    } else if state != RunState::Running {
        note = Some(format!("the run is {state:?}").to_lowercase());
    } else if exp.trial_duration_s > req.max_duration_s {
        note = Some(format!(
            "this run's trials last {} s, beyond the worker's limit of {} s",
            exp.trial_duration_s, req.max_duration_s
        ));
        st.sched
            .worker_seen(&req.worker, Some(req.slots), Instant::now());
    } else {
        let failed = &st.facts.failed;
        let mut rng = rand::rng();
        let taken = st.sched.take(
            &req.worker,
            req.slots,
            req.want,
            Instant::now(),
            &|t| failed.get(&t).cloned().unwrap_or_default(),
            &mut || rand::Rng::random::<u64>(&mut rng),
        );
        for (t, dispatch_id) in taken {
            let built = st
                .opened
                .get(&t.0)
                .ok_or_else(|| "its iteration is not open".to_string())
                .and_then(|o| {
                    crate::run::request(&st.facts.experiment, &st.facts.id, o, t.1, dispatch_id)
                        .map_err(|e| e.to_string())
                });
            match built {
                Ok(r) => {
                    st.dispatch += 1;
                    trials.push(r);
                }
                Err(e) => {
                    tracing::error!(iteration = t.0, trial = t.1, error = %e, "a queued trial has no request; dropped");
                    st.sched.forget(t);
                }
            }
        }
    }
    for d in st.sched.drain_latencies() {
        if st.counters.dispatch_ms.len() < 100_000 {
            #[allow(clippy::cast_possible_truncation)]
            st.counters
                .dispatch_ms
                .push((d.as_secs_f64() * 1000.0) as f32);
        }
    }
    if trials.is_empty() {
        st.counters.empty_grants += 1;
    }
    if !refused && (trials.len() < req.want as usize || st.sched.ready() == 0) {
        // The worker now believes nothing is ready here: tell it when
        // something is. Not for a worker of another fingerprint: nothing
        // changed here, and an advert would only bring its next request
        // (a worker of an older build asks again after every advert).
        st.advert.2 = true;
    }
    let grant = WorkGrant {
        trials,
        ready: u32::try_from(st.sched.ready()).unwrap_or(u32::MAX),
        running: u32::try_from(st.sched.in_flight()).unwrap_or(u32::MAX),
        seq: st.advert.0,
        state,
        note,
    };
    match grant.encode() {
        Ok(bytes) => {
            if let Err(e) = q.reply(q.key_expr().clone(), bytes).await {
                // The worker does not get them: their leases bring them back.
                tracing::warn!(worker = %req.worker, error = %e, "a work grant was not sent");
            }
        }
        Err(e) => tracing::error!(error = %e, "a work grant cannot be encoded"),
    }
    Ok(())
}

/// `naofarm ctl`: pause, resume, stop, priority; the run's thread journals
/// it, and the query is answered with the status once it has.
pub(super) async fn on_ctl(st: &mut State, q: zenoh::query::Query) -> Result<(), ServiceError> {
    let Some(payload) = q.payload() else {
        reply_err(&q, "a control request needs a ControlRequest payload").await;
        return Ok(());
    };
    let req = match ControlRequest::decode(&payload.to_bytes()) {
        Ok(r) => r,
        Err(e) => {
            st.refuse("an undecodable message", &format!("control: {e}"));
            reply_err(&q, &e.to_string()).await;
            return Ok(());
        }
    };
    let tag = st.tag();
    st.ctl_waiting.insert(tag, q);
    st.send(Cmd::Control {
        action: req.action,
        by: req.by,
        tag,
    })
}

/// The run's thread answered.
pub(super) async fn on_reply(
    session: &Session,
    st: &mut State,
    reply: Reply,
    events: Option<&tokio::sync::mpsc::UnboundedSender<Event>>,
) -> Result<(), ServiceError> {
    match reply {
        Reply::Applied {
            outcome: o,
            counted,
            effects,
            snapshot,
            took_s,
        } => {
            if let Some(snapshot) = snapshot {
                st.snap = *snapshot;
            }
            st.counters.decide_s += took_s;
            match counted {
                Counted::New => {
                    publish(session, &st.rkeys.trial(o.iteration, o.trial), o.as_ref()).await;
                }
                Counted::Duplicate => {
                    st.counters.duplicates += 1;
                    st.counters.accepted = st.counters.accepted.saturating_sub(1);
                }
            }
            handle_effects(session, st, effects, events).await?;
        }
        Reply::Failed {
            iteration,
            trial,
            verdict,
        } => match verdict {
            FailureVerdict::Retry => {}
            FailureVerdict::Ignored => {
                if !st.facts.pending.contains(&(iteration, trial)) {
                    st.sched.forget((iteration, trial));
                }
            }
            FailureVerdict::GiveUp(g) => return Err(ServiceError::GaveUp(g)),
        },
        Reply::Controlled {
            tag,
            action,
            by,
            result,
            snapshot,
        } => {
            st.snap = *snapshot;
            let q = st.ctl_waiting.remove(&tag);
            match result {
                Ok(()) => {
                    tracing::info!(?action, %by, "control");
                    if action == Control::Stop {
                        st.stopped = Some(by);
                    }
                    if let Some(q) = q {
                        reply_json(&q, st.status().to_json().map_err(|e| e.to_string())).await;
                    }
                }
                Err(why) => {
                    if let Some(q) = q {
                        reply_err(&q, &why).await;
                    }
                }
            }
        }
        Reply::Fatal(e) => return Err(e.into()),
    }
    Ok(())
}

pub(super) async fn reply_err(q: &zenoh::query::Query, why: &str) {
    if let Err(e) = q.reply_err(why.to_string()).await {
        tracing::warn!(error = %e, "an error reply failed");
    }
}

/// Answers a query with a JSON body; a body that could not be encoded is
/// logged and not answered (the querier sees no reply, never an empty one).
pub(super) async fn reply_json(q: &zenoh::query::Query, body: Result<String, String>) {
    match body {
        Ok(body) => {
            if let Err(e) = q
                .reply(q.key_expr().clone(), body)
                .encoding(Encoding::APPLICATION_JSON)
                .await
            {
                tracing::warn!(error = %e, "a query reply failed");
            }
        }
        Err(e) => tracing::error!(error = %e, "a query was not answered"),
    }
}

/// Answers a history query in parts of [`protocol::wire::HISTORY_PART`]
/// iterations, letting the link send each before the next: one reply of a
/// long history outgrew the link's queue, and the push that waited for room
/// held the very thread that makes room (the coordinator's one zenoh
/// thread), until zenoh closed the link.
pub(super) async fn reply_history(q: &zenoh::query::Query, history: &[IterationResult]) {
    if history.is_empty() {
        reply_json(q, Ok("[]".into())).await;
    }
    for part in history.chunks(protocol::wire::HISTORY_PART) {
        reply_json(q, serde_json::to_string(part).map_err(|e| e.to_string())).await;
        tokio::task::yield_now().await;
    }
}

/// Publishes a watched message in its JSON form (one that cannot be encoded is logged, not sent).
pub(super) async fn publish<M: WireMessage>(session: &Session, key: &str, message: &M) {
    match message.to_json() {
        Ok(body) => put_json(session, key, body).await,
        Err(e) => tracing::error!(key, error = %e, "not published"),
    }
}

pub(super) async fn put_json(session: &Session, key: &str, body: String) {
    // Block, not drop, under congestion: watchers count on every result.
    if let Err(e) = session
        .put(key, body)
        .encoding(Encoding::APPLICATION_JSON)
        .congestion_control(zenoh::qos::CongestionControl::Block)
        .await
    {
        tracing::warn!(key, error = %e, "publish failed");
    }
}

pub use protocol::measurement::PLAUSIBLE_DISTANCE_M;

/// Whether an outcome could be a real trial of `duration_s`.
pub(super) fn plausible(o: &TrialOutcome, duration_s: f64) -> Result<(), String> {
    o.measurement().plausible(duration_s)
}

pub(super) fn on_outcome(st: &mut State, o: TrialOutcome) -> Result<(), ServiceError> {
    let t = (o.iteration, o.trial);
    if st.facts.fingerprint.is_some_and(|f| f != o.fingerprint) {
        // Never journaled: the run's bits come from workers of one fingerprint.
        st.refuse(&o.worker, "outcome of another worker fingerprint");
        if st.sched.holder(t) == Some(o.worker.as_str()) {
            st.failed(t, &o.worker, "answered with another worker fingerprint")?;
        }
        return Ok(());
    }
    let answer = st.sched.answered(t, &o.worker, o.dispatch, Instant::now());
    if answer == Answer::WrongDispatch {
        // The holder answered under another id: it misbehaves; the trial fails on it.
        st.refuse(&o.worker, answer.reason());
        st.failed(t, &o.worker, "answered under a wrong dispatch id")?;
        return Ok(());
    }
    if answer != Answer::Held {
        // Never journaled: only the answer to a dispatch in flight counts
        // (a late answer after the lease passed included).
        st.refuse(&o.worker, answer.reason());
        return Ok(());
    }
    let duration = st.facts.experiment.trial_duration_s;
    if let Err(why) = plausible(&o, duration) {
        tracing::warn!(worker = %o.worker, iteration = o.iteration, trial = o.trial, %why, "an implausible outcome counts as a failure");
        st.failed(t, &o.worker, &format!("implausible outcome: {why}"))?;
        return Ok(());
    }
    let checked = st
        .opened
        .get(&t.0)
        .filter(|_| st.facts.pending.contains(&t))
        .ok_or_else(|| "trial not open".to_string())
        .and_then(|opened| decider::check(opened, o.trial, o.seed, &o.measurement()));
    if let Err(why) = checked {
        // Its worker answered the dispatch with something the run would refuse.
        st.refuse(&o.worker, &why);
        st.failed(t, &o.worker, &format!("refused outcome: {why}"))?;
        return Ok(());
    }
    st.facts.pending.remove(&t);
    st.sched.forget(t);
    st.ran_elsewhere(t, &o.worker);
    st.counters.accepted += 1;
    st.trials_done += 1;
    st.send(Cmd::Outcome(Box::new(o)))
}
