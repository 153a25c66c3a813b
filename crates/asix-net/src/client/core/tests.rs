//! The client state machine driven by a simulated clock: no sockets, no sleeping.

use std::net::{Ipv4Addr, SocketAddr};
use std::time::Duration;

use super::*;
use crate::proto::discovery::Resource;
use crate::proto::frame::{decode_frame, HelloAck};

const CH: &str = "K";

struct Harness {
    core: ClientCore,
    now: Now,
    events: Vec<ClientEvent>,
    sent: Vec<(LinkId, Frame)>,
    connects: Vec<(LinkId, SocketAddr)>,
    /// The fingerprint each connection must find (the announced one).
    connect_fps: Vec<Option<Fingerprint>>,
    closed: Vec<LinkId>,
    finds: Vec<FindServer>,
}

fn cfg() -> ClientConfig {
    let mut c = ClientConfig::new("CLI.", "CLI");
    c.options.find_server_timeout = Duration::from_millis(1000);
    c.options.net_timeout = Duration::from_millis(500);
    c.keepalive = Duration::from_millis(200);
    c.reconnect_interval = Duration::from_millis(300);
    c.retry_failed_items = Duration::from_millis(2000);
    c.discovery_resend = Duration::from_millis(250);
    let me = crate::tls::generate("CLI", None).unwrap();
    c.security =
        ClientSecurity::tls(&me.identity, crate::tls::Trust::Fingerprints(vec![PINNED])).unwrap();
    c
}

/// The fingerprint the test client pins and its servers announce.
const PINNED: Fingerprint = [0xA5; 32];

fn addr(port: u16) -> SocketAddr {
    SocketAddr::from((Ipv4Addr::LOCALHOST, port))
}

impl Harness {
    fn new(cfg: ClientConfig) -> Self {
        Harness {
            core: ClientCore::new(cfg),
            now: Now {
                mono: Instant::now(),
                wall: Timestamp(1_000_000),
            },
            events: Vec::new(),
            sent: Vec::new(),
            connects: Vec::new(),
            connect_fps: Vec::new(),
            closed: Vec::new(),
            finds: Vec::new(),
        }
    }

    fn pump(&mut self) {
        while let Some(a) = self.core.poll_action() {
            match a {
                Action::Event(e) => self.events.push(e),
                Action::Send { link, bytes } => {
                    let mut pos = 0;
                    while let Some((f, n)) = decode_frame(&bytes[pos..]).unwrap() {
                        self.sent.push((link, f));
                        pos += n;
                    }
                }
                Action::Connect {
                    link,
                    addr,
                    fingerprint,
                } => {
                    self.connects.push((link, addr));
                    self.connect_fps.push(fingerprint);
                }
                Action::Close { link } => self.closed.push(link),
                Action::SendFindServer(f) => self.finds.push(f),
            }
        }
    }

    /// Steps the clock by `ms`, firing every deadline on the way (as the shell would).
    fn advance(&mut self, ms: u64) {
        let end = self.now.mono + Duration::from_millis(ms);
        // Bounded: each round either fires a deadline at or before `end` or stops.
        for _ in 0..10_000 {
            match self.core.poll_timeout() {
                Some(t) if t <= end => {
                    let dt = t.saturating_duration_since(self.now.mono);
                    self.now.mono = self.now.mono.max(t);
                    self.now.wall = self.now.wall.add_millis(dt.as_millis() as u64);
                    self.core.handle_timeout(self.now);
                    self.pump();
                }
                _ => break,
            }
        }
        let dt = end.saturating_duration_since(self.now.mono);
        self.now.mono = end;
        self.now.wall = self.now.wall.add_millis(dt.as_millis() as u64);
        self.pump();
    }

    fn announce(&mut self, name: &str, flags: u8, port: u16) {
        self.announce_fp(name, flags, port, Some(PINNED));
    }

    fn announce_fp(&mut self, name: &str, flags: u8, port: u16, fingerprint: Option<Fingerprint>) {
        let find = self.finds.last().expect("a search is running").clone();
        let request = find.request;
        let a = Announce {
            request,
            server_name: name.into(),
            server_host: "H".into(),
            flags: ServerFlags(flags),
            clients: 0,
            tcp_port: port,
            fingerprint,
            resources: vec![Resource::channel(CH), find.resource],
        };
        self.core.handle_announce(self.now, a, addr(9));
        self.pump();
    }

    /// Completes the connection and handshake of the last link asked for.
    fn accept_last(&mut self, name: &str) -> LinkId {
        let (link, _) = *self.connects.last().unwrap();
        assert!(self.core.handle_connected(self.now, link));
        self.pump();
        let hello = self.last_request(link, |m| matches!(m, Message::Hello(_)));
        self.reply(
            link,
            hello,
            Message::HelloAck(HelloAck {
                status: 0,
                server_name: name.into(),
                flags: ServerFlags(0),
                clients: 0,
                idle_timeout_ms: 3000,
            }),
        );
        link
    }

    fn last_request(&self, link: LinkId, f: impl Fn(&Message) -> bool) -> u32 {
        self.sent
            .iter()
            .rev()
            .find(|(l, fr)| *l == link && f(&fr.msg))
            .map(|(_, fr)| fr.request)
            .expect("request sent")
    }

    fn reply(&mut self, link: LinkId, request: u32, msg: Message) {
        self.core
            .handle_frame(self.now, link, Frame { request, msg });
        self.pump();
    }

    fn handle_of(&self, link: LinkId, var: &str) -> u32 {
        self.sent
            .iter()
            .filter(|(l, _)| *l == link)
            .find_map(|(_, f)| match &f.msg {
                Message::Subscribe { items, .. } => items
                    .iter()
                    .find(|i| i.var.variable == var)
                    .map(|i| i.handle),
                _ => None,
            })
            .expect("subscribed")
    }

    fn subscribed_handles(&self, link: LinkId) -> Vec<u32> {
        self.sent
            .iter()
            .filter(|(l, _)| *l == link)
            .flat_map(|(_, f)| match &f.msg {
                Message::Subscribe { items, .. } => items.iter().map(|i| i.handle).collect(),
                _ => vec![],
            })
            .collect()
    }

    fn updates(&self) -> Vec<(ItemKey, Vqt)> {
        self.events
            .iter()
            .flat_map(|e| match e {
                ClientEvent::Updates(u) => u.clone(),
                _ => vec![],
            })
            .collect()
    }

    /// Subscribes `vars` and brings the channel up on server `name`.
    fn up_with(&mut self, vars: &[&str], name: &str, port: u16) -> LinkId {
        self.core.subscribe(
            self.now,
            vars.iter().map(|v| ItemKey::new(CH, v)).collect(),
            1000,
        );
        self.pump();
        self.announce(name, 0, port);
        self.accept_last(name)
    }
}

fn good(v: f32) -> Vqt {
    Vqt::new(Value::R4(v), Quality::GOOD, Timestamp(v as i64))
}

#[test]
fn link_loss_reports_last_known_value_or_comm_failure_once_then_good_after_resubscribe() {
    let mut h = Harness::new(cfg());
    let link = h.up_with(&["A", "B"], "S", 1);
    let handles = h.subscribed_handles(link);
    assert_eq!(handles.len(), 2);
    let ack = h.last_request(link, |m| matches!(m, Message::Subscribe { .. }));
    h.reply(
        link,
        ack,
        Message::SubscribeAck {
            results: handles.iter().map(|&x| (x, 0)).collect(),
        },
    );
    // Only A ever gets a value.
    let ha = h.handle_of(link, "A");
    h.core.handle_frame(
        h.now,
        link,
        Frame {
            request: 0,
            msg: Message::Update {
                items: vec![(ha, good(5.0))],
            },
        },
    );
    h.pump();
    h.events.clear();

    h.core
        .handle_link_failed(h.now, link, OpcError::NetCloseLink);
    h.pump();
    let ups = h.updates();
    assert_eq!(ups.len(), 2);
    let a = ups.iter().find(|(k, _)| &*k.variable == "A").unwrap();
    let b = ups.iter().find(|(k, _)| &*k.variable == "B").unwrap();
    assert_eq!(
        a.1,
        Vqt::new(Value::R4(5.0), Quality::BAD_LAST_KNOWN_VALUE, Timestamp(5))
    );
    assert_eq!(
        b.1,
        Vqt::new(Value::Empty, Quality::BAD_COMM_FAILURE, h.now.wall)
    );
    assert!(h.events.iter().any(|e| matches!(
        e,
        ClientEvent::ChannelDown {
            error: OpcError::NetCloseLink,
            ..
        }
    )));

    // A new search starts at once; failed rounds do not repeat the down qualities.
    h.events.clear();
    h.advance(1000 + 300 + 500); // two searches: the first failed, the second runs
    assert!(
        h.updates().is_empty(),
        "down qualities reported twice: {:?}",
        h.updates()
    );

    // A server answers; the items are subscribed again under the same handles.
    h.announce("S", 0, 1);
    let link2 = h.accept_last("S");
    assert_ne!(link, link2);
    let mut again = h.subscribed_handles(link2);
    again.sort_unstable();
    let mut before = handles.clone();
    before.sort_unstable();
    assert_eq!(again, before);
    h.core.handle_frame(
        h.now,
        link2,
        Frame {
            request: 0,
            msg: Message::Update {
                items: vec![(ha, good(6.0))],
            },
        },
    );
    h.pump();
    assert_eq!(h.updates().last().unwrap().1, good(6.0));
}

#[test]
fn an_unanswered_request_fails_with_net_answer_timeout_exactly_at_net_timeout() {
    let mut h = Harness::new(cfg());
    let link = h.up_with(&["Z"], "S", 1);
    h.core.read(
        h.now,
        77,
        vec![ItemKey::new(CH, "A"), ItemKey::new(CH, "B")],
        ReadSource::Driver,
    );
    h.pump();
    // The server keeps answering pings but never the read.
    for _ in 0..2 {
        h.advance(200);
        if let Some((_, f)) = h
            .sent
            .iter()
            .rev()
            .find(|(_, f)| matches!(f.msg, Message::Ping { .. }))
            .cloned()
        {
            let Message::Ping { nonce } = f.msg else {
                unreachable!()
            };
            h.reply(link, 0, Message::Pong { nonce });
        }
    }
    assert!(!h
        .events
        .iter()
        .any(|e| matches!(e, ClientEvent::ReadDone { .. })));
    h.advance(99);
    assert!(!h
        .events
        .iter()
        .any(|e| matches!(e, ClientEvent::ReadDone { .. })));
    h.advance(1);
    let done = h.events.iter().find_map(|e| match e {
        ClientEvent::ReadDone { id: 77, results } => Some(results.clone()),
        _ => None,
    });
    let results = done.expect("read completed at NetTimeout");
    assert!(results
        .iter()
        .all(|(_, r)| *r == Err(OpcError::NetAnswerTimeout)));
    assert!(
        h.closed.contains(&link),
        "a server that does not answer is dropped"
    );
}

#[test]
fn a_silent_server_is_dropped_by_keep_alive() {
    let mut h = Harness::new(cfg());
    let link = h.up_with(&["A"], "S", 1);
    let ack = h.last_request(link, |m| matches!(m, Message::Subscribe { .. }));
    let hs = h.subscribed_handles(link);
    h.reply(
        link,
        ack,
        Message::SubscribeAck {
            results: vec![(hs[0], 0)],
        },
    );
    h.advance(200); // ping sent
    assert!(h
        .sent
        .iter()
        .any(|(_, f)| matches!(f.msg, Message::Ping { .. })));
    h.advance(499);
    assert!(!h.closed.contains(&link));
    h.advance(1);
    assert!(h.closed.contains(&link));
    assert!(h.events.iter().any(|e| matches!(
        e,
        ClientEvent::ChannelDown {
            error: OpcError::NetAnswerTimeout,
            ..
        }
    )));
}

#[test]
fn a_named_server_is_the_only_one_reconnected_to() {
    let mut c = cfg();
    c.options.asix_server_name = "S".into();
    let mut h = Harness::new(c);
    let link = h.up_with(&["A"], "S", 1);
    h.core
        .handle_link_failed(h.now, link, OpcError::NetCloseLink);
    h.pump();
    let n = h.connects.len();
    h.announce("OTHER", ServerFlags::LOCAL, 2);
    assert_eq!(h.connects.len(), n, "connected to a server not named");
    h.announce("s", 0, 3);
    assert_eq!(h.connects.len(), n + 1);
    assert_eq!(h.connects.last().unwrap().1.port(), 3);
}

#[test]
fn without_stop_after_first_the_search_waits_and_ranks_then_falls_back_on_connect_failure() {
    let mut c = cfg();
    c.options.stop_after_first_server_found = false;
    let mut h = Harness::new(c);
    h.core.subscribe(h.now, vec![ItemKey::new(CH, "A")], 1000);
    h.pump();
    h.announce("BRIDGE", ServerFlags::BRIDGE, 1);
    h.announce("LOCAL", ServerFlags::LOCAL, 2);
    h.announce("FAILED", ServerFlags::SOURCE_FAILED | ServerFlags::LOCAL, 3);
    assert!(h.connects.is_empty(), "must wait for FindServerTimeout");
    h.advance(999);
    assert!(h.connects.is_empty());
    h.advance(1);
    assert_eq!(h.connects[0].1.port(), 2);
    // The best one refuses the connection: the next in rank is tried.
    let (l, _) = h.connects[0];
    h.core
        .handle_link_failed(h.now, l, OpcError::NetLinkToServer);
    h.pump();
    assert_eq!(h.connects[1].1.port(), 1);
}

#[test]
fn refused_items_report_config_error_and_are_retried_periodically() {
    let mut h = Harness::new(cfg());
    let link = h.up_with(&["NOPE"], "S", 1);
    let hs = h.subscribed_handles(link);
    let req = h.last_request(link, |m| matches!(m, Message::Subscribe { .. }));
    h.reply(
        link,
        req,
        Message::SubscribeAck {
            results: vec![(hs[0], OpcError::ItemUnknown.hresult())],
        },
    );
    assert!(h.events.iter().any(|e| matches!(
        e,
        ClientEvent::ItemFailed {
            error: OpcError::ItemUnknown,
            ..
        }
    )));
    assert_eq!(
        h.updates().last().unwrap().1.quality,
        Quality::BAD_CONFIG_ERROR
    );
    let subs_before = h.subscribed_handles(link).len();
    // Keep the link alive while waiting for the retry.
    for _ in 0..10 {
        h.advance(200);
        if let Some((_, f)) = h
            .sent
            .iter()
            .rev()
            .find(|(_, f)| matches!(f.msg, Message::Ping { .. }))
            .cloned()
        {
            let Message::Ping { nonce } = f.msg else {
                unreachable!()
            };
            h.reply(link, 0, Message::Pong { nonce });
        }
    }
    assert_eq!(
        h.subscribed_handles(link).len(),
        subs_before + 1,
        "subscribed again after retry_failed_items"
    );
}

#[test]
fn reads_and_writes_to_a_channel_without_server_fail_with_the_askom_codes() {
    let mut h = Harness::new(cfg());
    h.core
        .read(h.now, 1, vec![ItemKey::new(CH, "A")], ReadSource::Device);
    h.core
        .write(h.now, 2, vec![(ItemKey::new(CH, "A"), Value::R4(1.0))]);
    h.core.read(h.now, 3, vec![], ReadSource::Cache);
    h.pump();
    assert!(h
        .events
        .iter()
        .any(|e| matches!(e, ClientEvent::ReadDone { id: 3, results } if results.is_empty())));
    h.advance(1000);
    assert!(h
        .events
        .iter()
        .any(|e| matches!(e, ClientEvent::ReadDone { id: 1, results }
        if results[0].1 == Err(OpcError::NetFindServerNotFound))));
    assert!(h
        .events
        .iter()
        .any(|e| matches!(e, ClientEvent::WriteDone { id: 2, results }
        if results[0].1 == Err(OpcError::WriteErrorNetworkServerNotFound))));
}

#[test]
fn requests_spanning_channels_complete_once_in_request_order() {
    let mut h = Harness::new(cfg());
    let link = h.up_with(&["Z"], "S", 1);
    // Channel K is up; channel L has no server yet.
    h.core.read(
        h.now,
        9,
        vec![
            ItemKey::new("L", "X"),
            ItemKey::new(CH, "A"),
            ItemKey::new("L", "Y"),
        ],
        ReadSource::Cache,
    );
    h.pump();
    let req = h.last_request(link, |m| matches!(m, Message::Read { .. }));
    h.reply(
        link,
        req,
        Message::ReadResult {
            results: vec![Ok(good(1.0))],
        },
    );
    assert!(!h
        .events
        .iter()
        .any(|e| matches!(e, ClientEvent::ReadDone { .. })));
    // L is found on the same server: the link is shared.
    h.announce("S", 0, 1);
    let req = h.last_request(
        link,
        |m| matches!(m, Message::Read { items, .. } if items.len() == 2),
    );
    h.reply(
        link,
        req,
        Message::ReadResult {
            results: vec![Err(OpcError::ItemUnknown.hresult()), Ok(good(2.0))],
        },
    );
    let r = h.events.iter().find_map(|e| match e {
        ClientEvent::ReadDone { id: 9, results } => Some(results.clone()),
        _ => None,
    });
    let r = r.unwrap();
    assert_eq!(&*r[0].0.variable, "X");
    assert_eq!(r[0].1, Err(OpcError::ItemUnknown));
    assert_eq!(r[1].1, Ok(good(1.0)));
    assert_eq!(r[2].1, Ok(good(2.0)));
    assert_eq!(h.connects.len(), 1);
}

#[test]
fn only_pinned_announcements_lead_to_a_link_and_the_link_must_show_the_announced_certificate() {
    let mut h = Harness::new(cfg());
    h.core.subscribe(h.now, vec![ItemKey::new(CH, "V")], 1000);
    h.pump();
    // A server announcing another certificate, or none, is never tried.
    h.announce_fp("S1", 0, 1000, Some([0x5A; 32]));
    h.announce_fp("S1", 0, 1001, None);
    assert!(h.connects.is_empty());
    h.announce("S1", 0, 1002);
    assert_eq!(h.connects, [(1, addr(1002))]);
    assert_eq!(h.connect_fps, [Some(PINNED)]);
}

#[test]
fn a_client_without_tls_settings_links_to_nothing() {
    let mut c = cfg();
    c.security = ClientSecurity::default();
    let mut h = Harness::new(c);
    h.core.subscribe(h.now, vec![ItemKey::new(CH, "V")], 1000);
    h.pump();
    assert!(h.finds.is_empty(), "no search without a way to link");
    assert!(h.events.iter().any(|e| matches!(
        e,
        ClientEvent::ChannelDown {
            error: OpcError::NetLinkToServer,
            ..
        }
    )));
}
