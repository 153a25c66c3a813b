//! Choosing a server from the announcements (sans-IO; the client and [`crate::client::discover`]
//! drive it with explicit time).

use std::net::SocketAddr;
use std::time::{Duration, Instant};

use crate::config::ServerChoice;
use crate::proto::discovery::{Announce, Resource};

/// An announcing server that may be used.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Candidate {
    pub announce: Announce,
    /// The link address: the announcement's source IP and its TCP port.
    pub addr: SocketAddr,
}

impl Candidate {
    pub fn name(&self) -> &str {
        &self.announce.server_name
    }
}

/// Orders candidates by the manual's preferences, most preferred first: (a) data source not
/// failed, (b) local, (c) serves its own data rather than acting as a bridge, (d) fewest
/// clients; ties keep the order of arrival (the sort is stable).
pub fn rank(candidates: &mut [Candidate]) {
    candidates.sort_by_key(|c| {
        let f = c.announce.flags;
        (
            f.source_failed(),
            !f.local(),
            f.bridge(),
            c.announce.clients,
        )
    });
}

/// One search for a server offering a resource.
#[derive(Debug, Clone)]
pub struct Search {
    resource: Resource,
    choice: ServerChoice,
    /// Take the first acceptable answer (true for a named server, a list or LOCAL, and for
    /// "any server" with StopAfterFirstServerFound = tak).
    first_wins: bool,
    deadline: Instant,
    found: Vec<Candidate>,
    /// An announcement of an unpinned certificate was reported in this search.
    unpinned_reported: bool,
}

impl Search {
    pub fn new(
        resource: Resource,
        choice: ServerChoice,
        stop_after_first_server_found: bool,
        now: Instant,
        find_server_timeout: Duration,
    ) -> Self {
        let first_wins = stop_after_first_server_found || choice != ServerChoice::Any;
        Search {
            resource,
            choice,
            first_wins,
            deadline: now + find_server_timeout,
            found: Vec::new(),
            unpinned_reported: false,
        }
    }

    pub fn resource(&self) -> &Resource {
        &self.resource
    }
    pub fn deadline(&self) -> Instant {
        self.deadline
    }

    /// Does this announcement offer the resource from a server the choice allows?
    pub fn acceptable(&self, a: &Announce) -> bool {
        // An empty resource name accepts every server (variables addressed without channel).
        let offers = self.resource.name.is_empty()
            || a.resources
                .iter()
                .any(|r| r.kind == self.resource.kind && r.name == self.resource.name);
        offers && self.choice.allows(a)
    }

    /// Takes an announcement received from `from` (the datagram's source). Returns true when
    /// the search is complete.
    pub fn offer(&mut self, a: Announce, from: SocketAddr) -> bool {
        if self.acceptable(&a)
            && !self
                .found
                .iter()
                .any(|c| c.announce.server_name.eq_ignore_ascii_case(&a.server_name))
        {
            let addr = SocketAddr::new(from.ip(), a.tcp_port);
            self.found.push(Candidate { announce: a, addr });
        }
        self.is_done()
    }

    /// True the first time in this search: an announcement of an unpinned certificate is
    /// worth one warning per search, not one per resent request.
    pub fn first_unpinned(&mut self) -> bool {
        !std::mem::replace(&mut self.unpinned_reported, true)
    }

    /// Complete: the first acceptable answer arrived and it wins.
    pub fn is_done(&self) -> bool {
        self.first_wins && !self.found.is_empty()
    }

    /// The result: the candidates to try, in order (ranked unless the first answer wins).
    /// Empty means ASKOM_E_NetFindServer_NotFound.
    pub fn finish(mut self) -> Vec<Candidate> {
        if self.first_wins {
            self.found.truncate(1);
        } else {
            rank(&mut self.found);
        }
        self.found
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::proto::frame::ServerFlags;

    fn ann(name: &str, flags: u8, clients: u32) -> Announce {
        Announce {
            request: 1,
            server_name: name.into(),
            server_host: "H".into(),
            flags: ServerFlags(flags),
            clients,
            tcp_port: 1000,
            fingerprint: None,
            resources: vec![Resource::channel("K")],
        }
    }
    const FROM: SocketAddr =
        SocketAddr::new(std::net::IpAddr::V4(std::net::Ipv4Addr::LOCALHOST), 9);

    #[test]
    fn ranking_prefers_healthy_then_local_then_own_data_then_fewest_clients() {
        let t0 = Instant::now();
        let mut s = Search::new(
            Resource::channel("K"),
            ServerChoice::Any,
            false,
            t0,
            Duration::from_secs(1),
        );
        assert!(!s.offer(
            ann(
                "failed-local",
                ServerFlags::SOURCE_FAILED | ServerFlags::LOCAL,
                0
            ),
            FROM
        ));
        assert!(!s.offer(ann("bridge-1", ServerFlags::BRIDGE, 1), FROM));
        assert!(!s.offer(ann("remote-5", 0, 5), FROM));
        assert!(!s.offer(ann("remote-2", 0, 2), FROM));
        assert!(!s.offer(
            ann("local-bridge", ServerFlags::LOCAL | ServerFlags::BRIDGE, 0),
            FROM
        ));
        assert!(!s.offer(ann("local-9", ServerFlags::LOCAL, 9), FROM));
        let names: Vec<_> = s.finish().iter().map(|c| c.name().to_owned()).collect();
        assert_eq!(
            names,
            [
                "local-9",
                "local-bridge",
                "remote-2",
                "remote-5",
                "bridge-1",
                "failed-local"
            ]
        );
    }

    #[test]
    fn first_answer_wins_and_names_filter() {
        let t0 = Instant::now();
        let d = Duration::from_secs(1);
        let mut s = Search::new(Resource::channel("K"), ServerChoice::Any, true, t0, d);
        assert!(s.offer(ann("X", ServerFlags::SOURCE_FAILED, 0), FROM));
        assert_eq!(s.finish()[0].name(), "X");

        let list = ServerChoice::parse("B, C");
        let mut s = Search::new(Resource::channel("K"), list, false, t0, d);
        assert!(!s.offer(ann("A", ServerFlags::LOCAL, 0), FROM));
        assert!(s.offer(ann("c", 0, 0), FROM));
        assert_eq!(s.finish()[0].name(), "c");

        let mut s = Search::new(Resource::channel("K"), ServerChoice::Local, false, t0, d);
        assert!(!s.offer(ann("R", 0, 0), FROM));
        assert!(s.offer(ann("L", ServerFlags::LOCAL, 0), FROM));

        let mut s = Search::new(Resource::channel("OTHER"), ServerChoice::Any, true, t0, d);
        assert!(!s.offer(ann("A", 0, 0), FROM));
        assert!(s.finish().is_empty());
    }
}
