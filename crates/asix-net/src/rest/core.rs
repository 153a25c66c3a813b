//! The REST link as a sans-IO state machine: inputs are the user's requests,
//! [`RestCore::handle_answer`] and [`RestCore::handle_timeout`], each with the time
//! ([`Now`]); outputs are HTTP GETs ([`RestCore::poll_get`]) and [`ClientEvent`]s
//! ([`RestCore::poll_event`]); [`RestCore::poll_timeout`] says when to call
//! `handle_timeout` next. No clock, no socket, no HTTP (the shell, [`super::RestLink`],
//! does the requests and enforces their time limits).
//!
//! - **Polls**: every subscribed variable is polled at the fastest rate of the subscribed
//!   ones (at least [`MIN_POLL_MS`]); a poll is the subscribed names in batches of at most
//!   `max_batch` names, at most `max_in_flight` requests at a time. A poll still under way
//!   when the next falls due makes that one skipped, not queued.
//! - **Batches**: a station that answers a batch with one state per name, in order, batches;
//!   one that does not (fewer or more states, or other names) gets one name per request
//!   from then on, decided once per station and logged; the names of that answer are
//!   asked again one by one.
//! - **Failover**: the stations are tried in the configured order; a failed request (HTTP
//!   status, transport, time limit, malformed answer) makes its station fail: the channel is
//!   down (`ChannelDown`), the affected items get BAD Comm Failure keeping their last value,
//!   and the next station is polled at once; when every station failed in a row, the next
//!   round starts after `retry_interval`. While not on the first station, the preferred
//!   stations are probed every `come_back_interval` and the link comes back to the first
//!   that answers.
//! - **Quality**: the answer's OPC quality as it is (vendor and limit bits too) with its
//!   time; `readSucceeded: false` is BAD Config Error, logged once per variable with the
//!   server's text; a value the variable's type cannot hold is BAD Config Error for that
//!   variable (logged once), the other variables of the answer are unaffected.
//! - **Device reads**: one request per read call (in batches as above), to the current
//!   station; a failed one answers BAD Comm Failure with the last value.
//! - **Writes**: none (the API documents no write request; the network source refuses
//!   them).

use std::collections::{BTreeMap, HashMap, HashSet, VecDeque};
use std::fmt;
use std::sync::Arc;
use std::time::{Duration, Instant};

use asix_model::ItemKey;
use ctopc_core::{OpcError, Quality, Value, VarType, Vqt};
use tracing::{info, warn};

use super::decode::{RestValue, VarState};
use crate::client::core::{ClientEvent, Now, RequestId};

/// The fastest poll period, ms, whatever rate is asked.
pub const MIN_POLL_MS: u32 = 50;

/// A REST link's settings (no credential: the shell holds it).
#[derive(Debug, Clone)]
pub struct RestCoreConfig {
    /// The AsixConnect channel (for the events and the log).
    pub channel: Arc<str>,
    /// The stations' base URLs, in order of preference (never holding a credential).
    pub stations: Vec<String>,
    /// Most names in one request (>= 1).
    pub max_batch: usize,
    /// Most requests under way at once (>= 1), probes apart.
    pub max_in_flight: usize,
    /// Pause after every station failed in a row.
    pub retry_interval: Duration,
    /// How often a preferred station is probed while the link is on another.
    pub come_back_interval: Duration,
}

/// Why a request failed (the shell's report; its text never holds a credential).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FetchError {
    /// No complete answer within the time limit.
    Timeout,
    /// A non-2xx, non-3xx status.
    Status(u16),
    /// A redirect (3xx): not followed.
    Redirect(u16),
    /// The body is larger than the limit.
    TooLarge(usize),
    /// Connection, TLS or protocol failure.
    Transport(String),
    /// The body is not a decodable answer.
    Malformed(String),
}

impl fmt::Display for FetchError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FetchError::Timeout => f.write_str("no answer within the time limit"),
            FetchError::Status(s) => write!(f, "HTTP status {s}"),
            FetchError::Redirect(s) => write!(f, "redirect (HTTP status {s}) not followed"),
            FetchError::TooLarge(n) => write!(f, "answer larger than {n} bytes"),
            FetchError::Transport(e) => write!(f, "transport: {e}"),
            FetchError::Malformed(e) => write!(f, "{e}"),
        }
    }
}

/// Identifies one HTTP request of the core.
pub type GetId = u64;

/// An HTTP GET the shell must make: `base URL of station` + `path`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Get {
    pub id: GetId,
    pub station: usize,
    /// Path and query (`/asix/v1/variable/value?name=A&name=B`), percent-encoded.
    pub path: String,
    /// The names asked for, in order (the answer must have one state per name).
    pub names: Vec<Arc<str>>,
}

/// The path of a `variable/value` request for `names`.
pub fn values_path<S: AsRef<str>>(names: &[S]) -> String {
    let mut p = String::from("/asix/v1/variable/value");
    for (i, n) in names.iter().enumerate() {
        p.push(if i == 0 { '?' } else { '&' });
        p.push_str("name=");
        percent_encode(n.as_ref(), &mut p);
    }
    p
}

/// Percent-encodes a query value (RFC 3986 unreserved characters kept).
pub fn percent_encode(s: &str, out: &mut String) {
    for b in s.bytes() {
        if b.is_ascii_alphanumeric() || matches!(b, b'-' | b'_' | b'.' | b'~') {
            out.push(b as char);
        } else {
            out.push_str(&format!("%{b:02X}"));
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Batching {
    Unknown,
    Yes,
    Single,
}

#[derive(Debug)]
struct Var {
    /// The asix variable (the events' key).
    key: ItemKey,
    /// The type the variable's values are converted to (EMPTY: as answered).
    vt: VarType,
    rate: u32,
    last: Option<Vqt>,
    /// A failure quality was reported since the last answer.
    down: bool,
}

#[derive(Debug, Clone)]
enum Purpose {
    Poll,
    Read(RequestId),
    Probe,
}

#[derive(Debug)]
struct Request {
    purpose: Purpose,
    station: usize,
    /// (position in the read, key, type) for reads; position unused for polls.
    keys: Vec<(usize, ItemKey, VarType)>,
}

struct PendingRead {
    results: Vec<Option<(ItemKey, Result<Vqt, OpcError>)>>,
    left: usize,
}

/// The REST link's state machine.
pub struct RestCore {
    cfg: RestCoreConfig,
    vars: BTreeMap<ItemKey, Var>,
    station: usize,
    /// The channel is reported up on `station`.
    up: bool,
    /// Stations failed in a row since the last answer.
    failed_in_row: usize,
    batching: Vec<Batching>,
    next_poll: Option<Instant>,
    next_probe: Option<Instant>,
    /// Requests of the current poll not yet answered.
    poll_left: usize,
    queue: VecDeque<(GetId, Request)>,
    in_flight: HashMap<GetId, Request>,
    reads: HashMap<RequestId, PendingRead>,
    next_id: GetId,
    gets: VecDeque<Get>,
    events: VecDeque<ClientEvent>,
    updates: Vec<(ItemKey, Vqt)>,
    /// Stations whose single-name fallback was logged.
    logged_single: HashSet<usize>,
    /// Every station failed in a row: nothing is asked until the next poll.
    resting: bool,
    /// Variables whose readSucceeded=false or unconvertible value was logged (at most
    /// [`MAX_LOGGED`]; past that, no more such lines).
    logged: HashSet<ItemKey>,
}

/// The most variables whose failure [`RestCore`] remembers having logged.
const MAX_LOGGED: usize = 65_536;

/// `s` cut to at most `max` bytes (on a character boundary), for a log line.
fn cut(s: &str, max: usize) -> &str {
    if s.len() <= max {
        return s;
    }
    let mut end = max;
    while !s.is_char_boundary(end) {
        end -= 1;
    }
    &s[..end]
}

impl RestCore {
    pub fn new(mut cfg: RestCoreConfig) -> Self {
        cfg.max_batch = cfg.max_batch.max(1);
        cfg.max_in_flight = cfg.max_in_flight.max(1);
        let n = cfg.stations.len();
        RestCore {
            cfg,
            vars: BTreeMap::new(),
            station: 0,
            up: false,
            failed_in_row: 0,
            batching: vec![Batching::Unknown; n],
            next_poll: None,
            next_probe: None,
            poll_left: 0,
            queue: VecDeque::new(),
            in_flight: HashMap::new(),
            reads: HashMap::new(),
            next_id: 0,
            gets: VecDeque::new(),
            events: VecDeque::new(),
            updates: Vec::new(),
            logged_single: HashSet::new(),
            resting: false,
            logged: HashSet::new(),
        }
    }

    /// The station in use (index into the configured list).
    pub fn station(&self) -> usize {
        self.station
    }

    /// Whether the current station batches (`None`: not known yet).
    pub fn batches(&self, station: usize) -> Option<bool> {
        match self.batching.get(station)? {
            Batching::Unknown => None,
            Batching::Yes => Some(true),
            Batching::Single => Some(false),
        }
    }

    /// Subscribes variables (or changes their rate); `vt`: each one's canonical type.
    pub fn subscribe(&mut self, now: Now, keys: Vec<(ItemKey, VarType)>, rate: u32) {
        let mut new = false;
        for (key, vt) in keys {
            match self.vars.get_mut(&key) {
                Some(v) => {
                    v.rate = rate;
                    v.vt = vt;
                }
                None => {
                    new = true;
                    self.vars.insert(
                        key.clone(),
                        Var {
                            key,
                            vt,
                            rate,
                            last: None,
                            down: false,
                        },
                    );
                }
            }
        }
        if self.stations() == 0 {
            return;
        }
        if new || self.next_poll.is_none() {
            // New variables are polled at once (their first value is waited for).
            let at = if self.resting {
                self.next_poll.unwrap_or(now.mono)
            } else {
                now.mono
            };
            self.next_poll = Some(self.next_poll.map_or(at, |t| t.min(at)));
        }
    }

    pub fn unsubscribe(&mut self, keys: Vec<ItemKey>) {
        for k in keys {
            self.vars.remove(&k);
        }
        if self.vars.is_empty() {
            self.next_poll = None;
        }
    }

    /// Reads variables from the station now; completes with [`ClientEvent::ReadDone`].
    pub fn read(&mut self, _now: Now, id: RequestId, keys: Vec<(ItemKey, VarType)>) {
        if keys.is_empty() || self.stations() == 0 {
            let results = keys
                .into_iter()
                .map(|(k, _)| (k, Err(OpcError::NetInit)))
                .collect();
            self.events.push_back(ClientEvent::ReadDone { id, results });
            return;
        }
        self.reads.insert(
            id,
            PendingRead {
                results: (0..keys.len()).map(|_| None).collect(),
                left: keys.len(),
            },
        );
        let keys: Vec<_> = keys
            .into_iter()
            .enumerate()
            .map(|(i, (k, vt))| (i, k, vt))
            .collect();
        self.enqueue(Purpose::Read(id), self.station, keys);
        self.start_requests();
    }

    /// When [`RestCore::handle_timeout`] is next due.
    pub fn poll_timeout(&self) -> Option<Instant> {
        match (self.next_poll, self.next_probe) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    pub fn handle_timeout(&mut self, now: Now) {
        if self.next_poll.is_some_and(|t| t <= now.mono) {
            self.next_poll = None;
            self.start_poll(now);
        }
        if self.next_probe.is_some_and(|t| t <= now.mono) {
            self.next_probe = None;
            self.start_probes(now);
        }
    }

    /// The next request to make.
    pub fn poll_get(&mut self) -> Option<Get> {
        self.gets.pop_front()
    }

    /// The next event for the user.
    pub fn poll_event(&mut self) -> Option<ClientEvent> {
        if let Some(e) = self.events.pop_front() {
            return Some(e);
        }
        (!self.updates.is_empty()).then(|| ClientEvent::Updates(std::mem::take(&mut self.updates)))
    }

    /// Requests under way, probes included (the shell's concurrency: polls and reads
    /// start only while fewer than `max_in_flight` are under way; a round of probes, one
    /// per preferred station, may add to that).
    pub fn in_flight(&self) -> usize {
        self.in_flight.len()
    }

    fn stations(&self) -> usize {
        self.cfg.stations.len()
    }

    fn fastest_rate(&self) -> Option<u32> {
        self.vars.values().map(|v| v.rate).min()
    }

    fn batch_size(&self, station: usize) -> usize {
        match self.batching.get(station) {
            Some(Batching::Single) => 1,
            _ => self.cfg.max_batch,
        }
    }

    fn enqueue(&mut self, purpose: Purpose, station: usize, keys: Vec<(usize, ItemKey, VarType)>) {
        let size = self.batch_size(station);
        let mut it = keys.into_iter().peekable();
        while it.peek().is_some() {
            let chunk: Vec<_> = it.by_ref().take(size).collect();
            if matches!(purpose, Purpose::Poll) {
                self.poll_left += 1;
            }
            self.next_id += 1;
            self.queue.push_back((
                self.next_id,
                Request {
                    purpose: purpose.clone(),
                    station,
                    keys: chunk,
                },
            ));
        }
    }

    fn start_requests(&mut self) {
        while self.in_flight.len() < self.cfg.max_in_flight {
            let Some((id, r)) = self.queue.pop_front() else {
                break;
            };
            self.send(id, r);
        }
    }

    fn send(&mut self, id: GetId, r: Request) {
        let names: Vec<Arc<str>> = r.keys.iter().map(|(_, k, _)| k.variable.clone()).collect();
        self.gets.push_back(Get {
            id,
            station: r.station,
            path: values_path(&names),
            names,
        });
        self.in_flight.insert(id, r);
    }

    fn start_poll(&mut self, now: Now) {
        let Some(rate) = self.fastest_rate() else {
            return;
        };
        self.resting = false;
        self.next_poll = Some(now.mono + Duration::from_millis(u64::from(rate.max(MIN_POLL_MS))));
        if self.poll_left > 0 {
            // The last poll is still under way: this one is skipped.
            return;
        }
        let keys: Vec<_> = self
            .vars
            .values()
            .map(|v| (0, v.key.clone(), v.vt))
            .collect();
        self.enqueue(Purpose::Poll, self.station, keys);
        self.start_requests();
    }

    fn start_probes(&mut self, now: Now) {
        if self.station == 0 {
            return;
        }
        if self
            .in_flight
            .values()
            .any(|r| matches!(r.purpose, Purpose::Probe))
        {
            // The last probes are still under way (a slow station): ask again later.
            self.next_probe = Some(now.mono + self.cfg.come_back_interval);
            return;
        }
        // One subscribed name (any answer with one state will do), else the attribute list.
        let name = self.vars.keys().next().cloned();
        for s in 0..self.station {
            self.next_id += 1;
            let (path, names) = match &name {
                Some(k) => (values_path(&[&*k.variable]), vec![k.variable.clone()]),
                None => ("/asix/v1/server/variable/attribute".to_owned(), Vec::new()),
            };
            self.gets.push_back(Get {
                id: self.next_id,
                station: s,
                path,
                names,
            });
            let keys = name
                .iter()
                .map(|k| (0, k.clone(), VarType::EMPTY))
                .collect();
            self.in_flight.insert(
                self.next_id,
                Request {
                    purpose: Purpose::Probe,
                    station: s,
                    keys,
                },
            );
        }
    }

    /// The answer to a GET (`Ok`: the decoded states; a probe of the attribute list
    /// answers `Ok(vec![])`).
    pub fn handle_answer(
        &mut self,
        now: Now,
        id: GetId,
        answer: Result<Vec<VarState>, FetchError>,
    ) {
        let Some(r) = self.in_flight.remove(&id) else {
            return;
        };
        if matches!(r.purpose, Purpose::Probe) {
            self.probe_answer(now, r, answer);
            self.start_requests();
            return;
        }
        if matches!(r.purpose, Purpose::Poll) {
            self.poll_left = self.poll_left.saturating_sub(1);
        }
        match answer {
            Ok(states) if answer_matches(&r.keys, &states) => {
                if r.keys.len() > 1 {
                    self.batching[r.station] = Batching::Yes;
                }
                self.station_answered(now, r.station);
                for ((pos, key, vt), st) in r.keys.into_iter().zip(states) {
                    self.apply(now, &r.purpose, pos, key, vt, st);
                }
            }
            Ok(states) if r.keys.len() > 1 && states.len() <= r.keys.len() => {
                // One state per name in order, else the station does not batch.
                self.batching[r.station] = Batching::Single;
                if self.logged_single.insert(r.station) {
                    warn!(
                        channel = %self.cfg.channel,
                        station = %self.cfg.stations[r.station],
                        asked = r.keys.len(),
                        answered = states.len(),
                        "Asix.Evo REST: the station does not answer a batch of names with one state per name; asking one name per request from now on"
                    );
                }
                for k in r.keys {
                    self.enqueue(r.purpose.clone(), r.station, vec![k]);
                }
            }
            Ok(states) => {
                let e = FetchError::Malformed(format!(
                    "{} states for {} names",
                    states.len(),
                    r.keys.len()
                ));
                self.request_failed(now, r, e);
            }
            Err(e) => self.request_failed(now, r, e),
        }
        self.start_requests();
    }

    fn probe_answer(&mut self, now: Now, r: Request, answer: Result<Vec<VarState>, FetchError>) {
        let ok = match &answer {
            Ok(states) => r.keys.is_empty() || states.len() == 1,
            Err(_) => false,
        };
        if ok && r.station < self.station {
            info!(
                channel = %self.cfg.channel,
                station = %self.cfg.stations[r.station],
                "Asix.Evo REST: the preferred station answers again; coming back to it"
            );
            self.station = r.station;
            self.failed_in_row = 0;
            self.up = false;
            self.station_answered(now, r.station);
            if !self.vars.is_empty() {
                self.next_poll = Some(now.mono);
            }
        }
        if self.station > 0 && self.next_probe.is_none() {
            self.next_probe = Some(now.mono + self.cfg.come_back_interval);
        }
    }

    fn station_answered(&mut self, now: Now, station: usize) {
        if station != self.station {
            return;
        }
        self.failed_in_row = 0;
        if !self.up {
            self.up = true;
            self.events.push_back(ClientEvent::ChannelUp {
                channel: self.cfg.channel.clone(),
                server: self.cfg.stations[station].clone(),
            });
            if station > 0 && self.next_probe.is_none() {
                self.next_probe = Some(now.mono + self.cfg.come_back_interval);
            }
        }
    }

    fn apply(
        &mut self,
        now: Now,
        purpose: &Purpose,
        pos: usize,
        key: ItemKey,
        vt: VarType,
        st: VarState,
    ) {
        let channel = &self.cfg.channel;
        let logged = &mut self.logged;
        let mut log_once = |what: &str, text: &str| {
            if logged.len() < MAX_LOGGED && logged.insert(key.clone()) {
                let text = cut(text, 200);
                warn!(%channel, variable = %key.variable, status = %text, "Asix.Evo REST: {what}");
            }
        };
        let vqt = if !st.read_succeeded {
            log_once(
                "the station cannot read the variable (BAD Config Error)",
                &st.status,
            );
            Vqt::new(Value::Empty, Quality::BAD_CONFIG_ERROR, now.wall)
        } else {
            match convert(st.value, vt) {
                Ok(value) => Vqt::new(value, Quality(st.quality), st.time.unwrap_or(now.wall)),
                Err(why) => {
                    log_once(
                        "the value does not fit the variable's type (BAD Config Error)",
                        &why,
                    );
                    Vqt::new(Value::Empty, Quality::BAD_CONFIG_ERROR, now.wall)
                }
            }
        };
        match purpose {
            Purpose::Poll => {
                if let Some(v) = self.vars.get_mut(&key) {
                    v.down = false;
                    v.last = Some(vqt.clone());
                    self.updates.push((key, vqt));
                }
            }
            Purpose::Read(id) => self.read_result(*id, pos, key, Ok(vqt)),
            Purpose::Probe => {}
        }
    }

    fn read_result(&mut self, id: RequestId, pos: usize, key: ItemKey, r: Result<Vqt, OpcError>) {
        let Some(p) = self.reads.get_mut(&id) else {
            return;
        };
        if let Some(slot) = p.results.get_mut(pos) {
            if slot.is_none() {
                p.left -= 1;
            }
            *slot = Some((key, r));
        }
        if p.left == 0 {
            if let Some(p) = self.reads.remove(&id) {
                let results = p.results.into_iter().flatten().collect();
                self.events.push_back(ClientEvent::ReadDone { id, results });
            }
        }
    }

    fn request_failed(&mut self, now: Now, r: Request, e: FetchError) {
        let Request {
            purpose,
            station,
            keys,
        } = r;
        // The items of the request: BAD Comm Failure keeping the last value.
        match purpose {
            Purpose::Poll => self.mark_down(now, &keys),
            Purpose::Read(id) => {
                for (pos, key, _) in &keys {
                    let bad = self.comm_failure(now, key);
                    self.read_result(id, *pos, key.clone(), Ok(bad));
                }
            }
            Purpose::Probe => {}
        }
        let n = self.stations();
        if station == self.station && !self.resting {
            warn!(
                channel = %self.cfg.channel,
                station = %self.cfg.stations[station],
                error = %e,
                "Asix.Evo REST: request failed"
            );
            self.failed_in_row += 1;
            if self.up {
                self.up = false;
                self.events.push_back(ClientEvent::ChannelDown {
                    channel: self.cfg.channel.clone(),
                    error: match e {
                        FetchError::Timeout => OpcError::NetAnswerTimeout,
                        _ => OpcError::NetLinkToServerTimeout,
                    },
                });
            }
            self.next_probe = None;
            if self.failed_in_row >= n {
                warn!(
                    channel = %self.cfg.channel,
                    "Asix.Evo REST: no station answers; trying again in {} ms",
                    self.cfg.retry_interval.as_millis()
                );
                self.resting = true;
                self.failed_in_row = 0;
                self.station = 0;
                if !self.vars.is_empty() {
                    self.next_poll = Some(now.mono + self.cfg.retry_interval);
                }
                // The poll's requests not sent yet wait for the next round too.
                let queued = std::mem::take(&mut self.queue);
                for (id, q) in queued {
                    if matches!(q.purpose, Purpose::Poll) {
                        self.poll_left = self.poll_left.saturating_sub(1);
                        self.mark_down(now, &q.keys);
                    } else {
                        self.queue.push_back((id, q));
                    }
                }
            } else {
                self.station = (self.station + 1) % n;
            }
            // What was queued for the failed station goes to the next one.
            let to = self.station;
            for (_, q) in self.queue.iter_mut() {
                if q.station == station {
                    q.station = to;
                }
            }
        }
        // A failed poll's names are asked again of the station now in use, unless every
        // station just failed (the next poll is then after the pause).
        if matches!(purpose, Purpose::Poll) && !self.resting {
            let keys: Vec<_> = keys
                .into_iter()
                .filter(|(_, k, _)| self.vars.contains_key(k))
                .collect();
            if !keys.is_empty() {
                self.enqueue(Purpose::Poll, self.station, keys);
            }
        }
    }
}

impl RestCore {
    /// BAD Comm Failure with the variable's last value.
    fn comm_failure(&self, now: Now, key: &ItemKey) -> Vqt {
        let last = self.vars.get(key).and_then(|v| v.last.as_ref());
        let value = last.map_or(Value::Empty, |l| l.value.clone());
        Vqt::new(value, Quality::BAD_COMM_FAILURE, now.wall)
    }

    /// Reports subscribed variables BAD Comm Failure (once until their next answer).
    fn mark_down(&mut self, now: Now, keys: &[(usize, ItemKey, VarType)]) {
        for (_, key, _) in keys {
            let bad = self.comm_failure(now, key);
            if let Some(v) = self.vars.get_mut(key) {
                if !v.down {
                    v.down = true;
                    self.updates.push((key.clone(), bad));
                }
            }
        }
    }
}

/// One state per name, in order, each with the name asked (case-insensitive) or no name.
fn answer_matches(keys: &[(usize, ItemKey, VarType)], states: &[VarState]) -> bool {
    keys.len() == states.len()
        && keys.iter().zip(states).all(|((_, k, _), s)| {
            s.id.as_deref()
                .is_none_or(|id| id.eq_ignore_ascii_case(&k.variable))
        })
}

/// The answer's value as the variable's type holds it (`vt` EMPTY: as answered); the
/// error says why not.
pub fn convert(v: RestValue, vt: VarType) -> Result<Value, String> {
    let natural = match v {
        RestValue::Null => return Ok(Value::Empty),
        RestValue::Bool(b) => Value::Bool(b),
        RestValue::Int(i) => match i32::try_from(i) {
            Ok(i) => Value::I4(i),
            Err(_) => Value::I8(i),
        },
        RestValue::UInt(u) => Value::UI8(u),
        RestValue::Float(f) => Value::R8(f),
        RestValue::Text(s) => Value::Bstr(s),
        RestValue::Unsupported => return Err("an object or array value".into()),
    };
    if vt == VarType::EMPTY || natural.var_type() == vt {
        return Ok(natural);
    }
    let from = natural.var_type();
    natural
        .convert(vt)
        .map_err(|e| format!("a {from:?} value as {vt:?}: {e}"))
}

#[cfg(test)]
mod tests;
