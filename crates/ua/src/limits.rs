//! The server's limits (`[UA]`'s `Max…` options): their check, their mapping onto
//! async-opcua's limits and decoding options, the total of monitored items and the
//! request rate of a session.
//!
//! What answers what when a limit is exceeded:
//!
//! | limit | enforced by | answer |
//! |---|---|---|
//! | `MaxSessions` | async-opcua | Bad_TooManySessions |
//! | `MaxSubscriptionsPerSession` | async-opcua | Bad_TooManySubscriptions |
//! | `MaxMonitoredItemsPerSubscription` | async-opcua | Bad_TooManyMonitoredItems |
//! | `MaxMonitoredItems` (every session's, of the plant's variables) | [`ItemBudget`] | Bad_TooManyMonitoredItems |
//! | `MaxBrowseContinuationPoints` (per session) | async-opcua | Bad_NoContinuationPoints |
//! | `MaxOperationsPerRequest` (Read, Write, Browse, RegisterNodes, TranslateBrowsePaths, monitored items per call) | async-opcua | Bad_TooManyOperations |
//! | `MaxMessageSize`, `MaxChunkCount` | async-opcua's transport | Bad_RequestTooLarge / Bad_TcpMessageTooLarge, the channel closed |
//! | `MaxArrayLength`, `MaxStringLength` | async-opcua's decoder | Bad_DecodingError (the request is not decoded) |
//! | `MaxRequestsPerSecond` (per session) | [`RateLimiter`], for the requests reaching the plant's node manager | Bad_TooManyOperations |
//!
//! async-opcua answers the limits it counts with their code but logs nothing; the two
//! counted here log a warning (the request rate once per run of refusals).
//!
//! Subscriptions in total are bounded by `MaxSessions` × `MaxSubscriptionsPerSession`:
//! async-opcua 0.19 counts subscriptions per session only. Its request dispatch has no
//! hook in front of the services, so the request rate is counted where the requests reach
//! the plant's node manager (Read, Write, Browse, which TranslateBrowsePaths goes
//! through, the creation of monitored items); Publish, the subscription services and those answered by the core
//! namespace alone are not counted (each of those is bounded by its own limit above).

use opcua::core::{Message, RequestMessage};
use opcua::types::{
    BinaryDecodable, ContextOwned, DecodingOptions, NamespaceMap, NodeId, StatusCode,
};
use std::collections::HashMap;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// The limits, as `[UA]` sets them.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Limits {
    pub max_sessions: usize,
    pub max_subscriptions_per_session: usize,
    pub max_monitored_items_per_subscription: usize,
    /// Monitored items of the plant's variables, every session's together.
    pub max_monitored_items: usize,
    /// Browse continuation points a session holds at once.
    pub max_browse_continuation_points: usize,
    /// Operations in one request (nodes of a Read, Write, Browse, RegisterNodes or
    /// TranslateBrowsePaths; monitored items of one create/modify/delete).
    pub max_operations_per_request: usize,
    /// Bytes of one message (every chunk together).
    pub max_message_size: usize,
    /// Chunks of one message.
    pub max_chunk_count: usize,
    /// Elements of one array in a request.
    pub max_array_length: usize,
    /// Bytes of one string (and of one byte string) in a request.
    pub max_string_length: usize,
    /// Requests a session may make per second (a token bucket of one second's worth);
    /// 0: no limit.
    pub max_requests_per_second: u32,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            max_sessions: 100,
            max_subscriptions_per_session: 100,
            max_monitored_items_per_subscription: 100_000,
            max_monitored_items: 1_000_000,
            max_browse_continuation_points: 100,
            max_operations_per_request: 10_000,
            max_message_size: 16 * 1024 * 1024,
            max_chunk_count: 512,
            max_array_length: 100_000,
            max_string_length: 65_535,
            max_requests_per_second: 10_000,
        }
    }
}

/// The smallest message a server must accept (OPC UA Part 6: 8192-byte buffers).
pub const MIN_MESSAGE_SIZE: usize = 8192;

impl Limits {
    /// Checks the limits together: `Err` names the first one that cannot work.
    pub fn check(&self) -> Result<(), String> {
        let at_least_one = [
            ("MaxSessions", self.max_sessions),
            (
                "MaxSubscriptionsPerSession",
                self.max_subscriptions_per_session,
            ),
            (
                "MaxMonitoredItemsPerSubscription",
                self.max_monitored_items_per_subscription,
            ),
            ("MaxMonitoredItems", self.max_monitored_items),
            (
                "MaxBrowseContinuationPoints",
                self.max_browse_continuation_points,
            ),
            ("MaxOperationsPerRequest", self.max_operations_per_request),
            ("MaxChunkCount", self.max_chunk_count),
            ("MaxArrayLength", self.max_array_length),
        ];
        if let Some((name, _)) = at_least_one.iter().find(|(_, v)| *v == 0) {
            return Err(format!("{name} must be at least 1"));
        }
        if self.max_message_size < MIN_MESSAGE_SIZE {
            return Err(format!(
                "MaxMessageSize must be at least {MIN_MESSAGE_SIZE}"
            ));
        }
        // A server certificate and a client's nonce must fit in a string.
        if self.max_string_length < 4096 {
            return Err("MaxStringLength must be at least 4096".to_owned());
        }
        Ok(())
    }

    /// Sets async-opcua's limits from these (the ones not named here keep its defaults).
    pub fn apply(&self, l: &mut opcua::server::Limits) {
        l.max_sessions = self.max_sessions;
        l.max_message_size = self.max_message_size;
        l.max_chunk_count = self.max_chunk_count;
        l.max_array_length = self.max_array_length;
        l.max_string_length = self.max_string_length;
        l.max_byte_string_length = self.max_string_length;
        l.max_browse_continuation_points = self.max_browse_continuation_points;
        let s = &mut l.subscriptions;
        s.max_subscriptions_per_session = self.max_subscriptions_per_session;
        s.max_monitored_items_per_sub = self.max_monitored_items_per_subscription;
        let ops = self.max_operations_per_request;
        let o = &mut l.operational;
        o.max_nodes_per_read = ops;
        o.max_nodes_per_write = ops;
        o.max_nodes_per_browse = ops;
        o.max_nodes_per_register_nodes = ops;
        o.max_nodes_per_translate_browse_paths_to_node_ids = ops;
        o.max_monitored_items_per_call = ops;
    }

    /// The decoding options async-opcua decodes a request with under these limits.
    pub fn decoding_options(&self) -> DecodingOptions {
        DecodingOptions {
            max_message_size: self.max_message_size,
            max_chunk_count: self.max_chunk_count,
            max_string_length: self.max_string_length,
            max_byte_string_length: self.max_string_length,
            max_array_length: self.max_array_length,
            ..DecodingOptions::default()
        }
    }

    /// The start line's account of the limits.
    pub fn describe(&self) -> String {
        let rate = match self.max_requests_per_second {
            0 => "no request rate limit".to_owned(),
            r => format!("{r} requests/s per session"),
        };
        format!(
            "limits: {} sessions, {} subscriptions per session, {} monitored items per \
             subscription and {} in all, {} operations per request, messages of {} bytes, {rate}",
            self.max_sessions,
            self.max_subscriptions_per_session,
            self.max_monitored_items_per_subscription,
            self.max_monitored_items,
            self.max_operations_per_request,
            self.max_message_size,
        )
    }
}

/// Decodes a request's body (its type's NodeId, then the request) as async-opcua decodes
/// a message's chunks once joined, with these limits: `Err` is the status code the
/// request is refused with.
pub fn decode_request(body: &[u8], limits: &Limits) -> Result<RequestMessage, StatusCode> {
    if body.len() > limits.max_message_size {
        return Err(StatusCode::BadRequestTooLarge);
    }
    let owned = ContextOwned::new_default(NamespaceMap::new(), limits.decoding_options());
    let ctx = owned.context();
    let mut stream = std::io::Cursor::new(body);
    let node_id = NodeId::decode(&mut stream, &ctx).map_err(|e| e.status())?;
    let object_id = node_id
        .as_object_id()
        .map_err(|_| StatusCode::BadServiceUnsupported)?;
    RequestMessage::decode_by_object_id(&mut stream, object_id, &ctx).map_err(|e| e.status())
}

/// The monitored items of the plant's variables, every session's together, against
/// `MaxMonitoredItems`.
#[derive(Debug)]
pub struct ItemBudget {
    max: usize,
    used: AtomicUsize,
}

impl ItemBudget {
    pub fn new(max: usize) -> Self {
        ItemBudget {
            max,
            used: AtomicUsize::new(0),
        }
    }

    /// Takes one item: Bad_TooManyMonitoredItems (and a log line) when none is left.
    pub fn take(&self) -> Result<(), StatusCode> {
        let taken = self
            .used
            .fetch_update(Ordering::AcqRel, Ordering::Acquire, |n| {
                (n < self.max).then_some(n + 1)
            });
        taken.map(|_| ()).map_err(|_| {
            tracing::warn!(
                "OPC UA: a monitored item refused: the server has its MaxMonitoredItems ({})",
                self.max
            );
            StatusCode::BadTooManyMonitoredItems
        })
    }

    /// Gives one item back.
    pub fn give_back(&self) {
        let _ = self
            .used
            .fetch_update(Ordering::AcqRel, Ordering::Acquire, |n| n.checked_sub(1));
    }

    pub fn used(&self) -> usize {
        self.used.load(Ordering::Acquire)
    }
}

/// A token bucket: `rate` tokens a second, holding at most one second's worth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TokenBucket {
    tokens: f64,
    last: Instant,
}

impl TokenBucket {
    /// A full bucket at `now`.
    pub fn full(rate: u32, now: Instant) -> Self {
        TokenBucket {
            tokens: f64::from(rate),
            last: now,
        }
    }

    /// Refills for the time since the last call and takes one token if there is one.
    pub fn admit(&mut self, rate: u32, now: Instant) -> bool {
        let elapsed = now.saturating_duration_since(self.last).as_secs_f64();
        self.last = self.last.max(now);
        let cap = f64::from(rate);
        self.tokens = (self.tokens + elapsed * cap).min(cap);
        if self.tokens >= 1.0 {
            self.tokens -= 1.0;
            true
        } else {
            false
        }
    }
}

/// How long a session's bucket is kept without a request (a full bucket then, so
/// forgetting it changes nothing).
const IDLE: Duration = Duration::from_secs(2);

/// The request rate of every session: one token bucket per session id. Buckets idle
/// for [`IDLE`] are dropped when the map holds more than `max_sessions`, so the map
/// stays near the number of active sessions.
#[derive(Debug)]
pub struct RateLimiter {
    rate: u32,
    max_sessions: usize,
    /// Each session's bucket and the requests refused since it last admitted one (one
    /// log line at the first refusal and one when it admits again, not one per request).
    buckets: Mutex<HashMap<u32, (TokenBucket, u64)>>,
}

impl RateLimiter {
    pub fn new(rate: u32, max_sessions: usize) -> Self {
        RateLimiter {
            rate,
            max_sessions,
            buckets: Mutex::new(HashMap::new()),
        }
    }

    /// Admits one request of `session` at `now`: Bad_TooManyOperations when the session
    /// is over its rate (a warning line at the first refusal of a run of them, and a
    /// line with their count when the session is admitted again).
    pub fn admit(&self, session: u32, now: Instant) -> Result<(), StatusCode> {
        if self.rate == 0 {
            return Ok(());
        }
        let mut b = self.buckets.lock().unwrap_or_else(|p| p.into_inner());
        if !b.contains_key(&session) && b.len() >= self.max_sessions {
            b.retain(|_, (t, _)| now.saturating_duration_since(t.last) < IDLE);
        }
        let rate = self.rate;
        let (bucket, refused) = b
            .entry(session)
            .or_insert_with(|| (TokenBucket::full(rate, now), 0));
        if bucket.admit(rate, now) {
            if *refused > 0 {
                tracing::info!(
                    "OPC UA: session {session} admitted again after {refused} requests refused over MaxRequestsPerSecond"
                );
                *refused = 0;
            }
            Ok(())
        } else {
            if *refused == 0 {
                tracing::warn!(
                    "OPC UA: refusing requests of session {session}: over MaxRequestsPerSecond ({rate})"
                );
            }
            *refused += 1;
            Err(StatusCode::BadTooManyOperations)
        }
    }

    /// The sessions with a bucket.
    pub fn sessions(&self) -> usize {
        self.buckets.lock().unwrap_or_else(|p| p.into_inner()).len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_defaults_pass_and_each_impossible_limit_is_named() {
        Limits::default().check().unwrap();
        type Case = (fn(&mut Limits), &'static str);
        let cases: [Case; 5] = [
            (|l| l.max_sessions = 0, "MaxSessions"),
            (|l| l.max_monitored_items = 0, "MaxMonitoredItems"),
            (|l| l.max_chunk_count = 0, "MaxChunkCount"),
            (|l| l.max_message_size = 8191, "MaxMessageSize"),
            (|l| l.max_string_length = 100, "MaxStringLength"),
        ];
        for (set, name) in cases {
            let mut l = Limits::default();
            set(&mut l);
            let e = l.check().unwrap_err();
            assert!(e.starts_with(name), "{e}");
        }
    }

    #[test]
    fn the_limits_map_onto_async_opcua_and_its_decoding() {
        let l = Limits {
            max_sessions: 2,
            max_subscriptions_per_session: 3,
            max_monitored_items_per_subscription: 4,
            max_monitored_items: 5,
            max_browse_continuation_points: 6,
            max_operations_per_request: 7,
            max_message_size: 80_000,
            max_chunk_count: 9,
            max_array_length: 10,
            max_string_length: 5000,
            max_requests_per_second: 12,
        };
        let mut o = opcua::server::Limits::default();
        l.apply(&mut o);
        assert_eq!(
            (o.max_sessions, o.max_message_size, o.max_chunk_count),
            (2, 80_000, 9)
        );
        assert_eq!(
            (
                o.max_array_length,
                o.max_string_length,
                o.max_byte_string_length
            ),
            (10, 5000, 5000)
        );
        assert_eq!(o.max_browse_continuation_points, 6);
        assert_eq!(o.subscriptions.max_subscriptions_per_session, 3);
        assert_eq!(o.subscriptions.max_monitored_items_per_sub, 4);
        let p = &o.operational;
        for n in [
            p.max_nodes_per_read,
            p.max_nodes_per_write,
            p.max_nodes_per_browse,
            p.max_nodes_per_register_nodes,
            p.max_nodes_per_translate_browse_paths_to_node_ids,
            p.max_monitored_items_per_call,
        ] {
            assert_eq!(n, 7);
        }
        let d = l.decoding_options();
        assert_eq!(
            (
                d.max_message_size,
                d.max_chunk_count,
                d.max_array_length,
                d.max_string_length,
                d.max_byte_string_length
            ),
            (80_000, 9, 10, 5000, 5000)
        );
    }

    #[test]
    fn the_item_budget_refuses_past_its_maximum_and_takes_back() {
        let b = ItemBudget::new(2);
        assert_eq!((b.take(), b.take()), (Ok(()), Ok(())));
        assert_eq!(b.take(), Err(StatusCode::BadTooManyMonitoredItems));
        b.give_back();
        assert_eq!(b.used(), 1);
        assert_eq!(b.take(), Ok(()));
        b.give_back();
        b.give_back();
        b.give_back();
        assert_eq!(b.used(), 0, "never below zero");
    }

    #[test]
    fn a_bucket_admits_its_rate_a_second_and_refills_with_time() {
        let t0 = Instant::now();
        let mut b = TokenBucket::full(3, t0);
        assert!((0..3).all(|_| b.admit(3, t0)));
        assert!(!b.admit(3, t0));
        assert!(!b.admit(3, t0 + Duration::from_millis(300)));
        assert!(b.admit(3, t0 + Duration::from_millis(340)));
        // A long pause refills one second's worth, no more.
        let later = t0 + Duration::from_secs(60);
        assert_eq!((0..10).filter(|_| b.admit(3, later)).count(), 3);
        // A time before the last one takes nothing back.
        assert!(!b.admit(3, t0));
    }

    #[test]
    fn the_rate_limiter_counts_per_session_and_forgets_idle_sessions() {
        let t0 = Instant::now();
        let r = RateLimiter::new(2, 2);
        assert_eq!(r.admit(1, t0), Ok(()));
        assert_eq!(r.admit(1, t0), Ok(()));
        assert_eq!(r.admit(1, t0), Err(StatusCode::BadTooManyOperations));
        assert_eq!(r.admit(2, t0), Ok(()), "another session has its own bucket");
        // A third session past max_sessions drops the idle buckets.
        let later = t0 + IDLE + Duration::from_millis(1);
        assert_eq!(r.admit(3, later), Ok(()));
        assert_eq!(r.sessions(), 1);
        let off = RateLimiter::new(0, 1);
        assert!((0..1000).all(|i| off.admit(i, t0).is_ok()));
        assert_eq!(off.sessions(), 0);
    }

    /// A Read of `n` nodes, encoded as a request body.
    pub fn read_request(n: usize) -> Vec<u8> {
        use opcua::types::{BinaryEncodable, ObjectId, ReadRequest, ReadValueId};
        let req = ReadRequest {
            nodes_to_read: Some(
                (0..n)
                    .map(|i| ReadValueId::from(NodeId::new(2, format!("KW_A{i:03}"))))
                    .collect(),
            ),
            ..Default::default()
        };
        let owned = ContextOwned::default();
        let ctx = owned.context();
        let mut out = Vec::new();
        NodeId::from(ObjectId::ReadRequest_Encoding_DefaultBinary)
            .encode(&mut out, &ctx)
            .unwrap();
        req.encode(&mut out, &ctx).unwrap();
        out
    }

    #[test]
    fn requests_decode_within_the_limits_and_are_refused_past_them() {
        let body = read_request(20);
        let l = Limits::default();
        match decode_request(&body, &l) {
            Ok(RequestMessage::Read(r)) => {
                assert_eq!(r.nodes_to_read.map(|v| v.len()), Some(20))
            }
            other => panic!("{other:?}"),
        }
        let short = Limits {
            max_array_length: 10,
            ..Limits::default()
        };
        assert_eq!(
            decode_request(&body, &short).unwrap_err(),
            StatusCode::BadDecodingError
        );
        let small = Limits {
            max_message_size: body.len() - 1,
            ..Limits::default()
        };
        assert_eq!(
            decode_request(&body, &small).unwrap_err(),
            StatusCode::BadRequestTooLarge
        );
        assert!(decode_request(&body[..body.len() - 3], &l).is_err());
        assert!(decode_request(&[], &l).is_err());
    }

    #[test]
    fn the_start_line_names_the_limits() {
        let d = Limits::default().describe();
        assert_eq!(
            d,
            "limits: 100 sessions, 100 subscriptions per session, 100000 monitored items \
             per subscription and 1000000 in all, 10000 operations per request, messages \
             of 16777216 bytes, 10000 requests/s per session"
        );
    }
}
