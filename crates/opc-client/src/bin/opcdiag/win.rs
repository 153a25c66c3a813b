//! The commands, through COM (Windows only). Every call goes through the safe client
//! wrapper `opc_client`; errors become one line with the HRESULT, its symbol and
//! the server's text for it (IOPCCommon::GetErrorString), else the system's.

use crate::cli::{Command, Global, EXIT_FAILED, EXIT_OK, EXIT_USAGE};
use crate::text::{self, TreeLine};
use ctopc_com::apartment::Apartment;
use ctopc_com::interfaces::*;
use ctopc_core::{Timestamp, VarType};
use opc_client::diag;
use opc_client::sink::{Callback, Options, Recording};
use opc_client::{self as client, GroupSpec, ItemDef, OpcGroup, ReadItem, Server};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::time::{Duration, Instant};
use windows::core::{Interface, HRESULT};

/// Elements asked for per IOPCBrowse::Browse call (`dwMaxElementsReturned`): large pages,
/// bounded so that one reply stays a few megabytes.
const BROWSE_BATCH: u32 = 10_000;

/// Names between two progress lines on stderr.
const PROGRESS_EVERY: usize = 10_000;

/// Progress of a long listing on stderr: a line every PROGRESS_EVERY names, and a last
/// one when at least one was printed. Short listings (the demo's) print nothing.
struct Progress {
    what: &'static str,
    n: usize,
    next: usize,
    start: Instant,
}

impl Progress {
    fn new(what: &'static str) -> Progress {
        Progress {
            what,
            n: 0,
            next: PROGRESS_EVERY,
            start: Instant::now(),
        }
    }

    fn add(&mut self, k: usize) {
        self.n += k;
        if self.n >= self.next {
            self.line();
            self.next = (self.n / PROGRESS_EVERY + 1) * PROGRESS_EVERY;
        }
    }

    fn line(&self) {
        eprintln!(
            "opcdiag: browse: {} {} ({:.1} s)",
            self.n,
            self.what,
            self.start.elapsed().as_secs_f64()
        );
    }

    /// The final count, when progress lines were printed.
    fn done(&self) {
        if self.n >= PROGRESS_EVERY {
            self.line();
        }
    }
}

/// A connection to one server object, with COM initialised for it.
pub struct Session {
    // Declared before `_com`: released before COM is uninitialised.
    pub server: Server,
    pub progid: String,
    _com: Apartment,
}

/// Runs a command but `demo` (main runs it through `demo::run`, which builds on this
/// module); `Err` is a failure to report (exit code 1).
pub fn run(global: &Global, command: Command) -> Result<u8, String> {
    if command == Command::Servers {
        return servers();
    }
    if let Command::Doctor(options) = command {
        return Ok(crate::doctor::run(global, &options));
    }
    let s = Session::connect(global)?;
    match command {
        Command::Status => s.status().map(|()| EXIT_OK),
        Command::Browse {
            flat,
            branch,
            depth,
            // OPC UA's BrowseNext paging; DA's browse enumerates.
            page: _,
        } => s.browse(flat, branch.as_deref(), depth),
        Command::Props { item } => s.props(&item),
        Command::Read {
            items,
            device,
            path,
        } => s.read(&items, device, &path),
        Command::Write {
            item,
            value,
            vt,
            path,
        } => s.write(&item, &value, vt, &path),
        Command::Subscribe {
            items,
            rate_ms,
            for_secs,
            count,
            path,
        } => s.subscribe(&items, rate_ms, for_secs, count, &path),
        Command::Demo { .. } => Err("demo runs from main".into()),
        Command::Servers => servers(),
        Command::Doctor(_) => Err("doctor runs without a session".into()),
        Command::ExportDb { .. } => Err("export-db runs from main".into()),
        Command::Cert => Err("cert runs from main".into()),
    }
}

/// `opcdiag servers`: the machine's OPC DA servers through OPC.ServerList.1, else the
/// component categories manager.
fn servers() -> Result<u8, String> {
    use ctopc_registration::{guid_string, VIEWS};
    use opc_client::server_list::{classes_by_category_manager, ServerBrowser};
    use windows::core::GUID;
    let _com = Apartment::mta().map_err(|e| format!("CoInitializeEx: {e}"))?;
    let categories = [
        (CATID_OPCDAServer10, "1.0"),
        (CATID_OPCDAServer20, "2.0"),
        (CATID_OPCDAServer30, "3.0"),
    ];
    let browser = ServerBrowser::connect();
    let mut found: Vec<(GUID, Vec<&'static str>)> = Vec::new();
    for (catid, version) in categories {
        let ids = match &browser {
            Ok(b) => b.classes(&[catid], &[]),
            Err(_) => classes_by_category_manager(&[catid]),
        }
        .map_err(|e| format!("listing DA {version} servers: {e}"))?;
        for id in ids {
            match found.iter_mut().find(|(g, _)| *g == id) {
                Some((_, v)) => v.push(version),
                None => found.push((id, vec![version])),
            }
        }
    }
    let registry_text = |path: String| {
        VIEWS
            .iter()
            .find_map(|&v| ctopc_com::winreg::read_default(v, &path))
    };
    let rows: Vec<text::ServerRow> = found
        .into_iter()
        .map(|(id, versions)| {
            let clsid = guid_string(id.to_u128());
            let (progid, description) = match browser.as_ref().map(|b| b.details(&id)) {
                Ok(Ok(d)) => (d.progid, d.user_type),
                _ => (
                    registry_text(format!("CLSID\\{clsid}\\ProgID")).unwrap_or_default(),
                    registry_text(format!("CLSID\\{clsid}")).unwrap_or_default(),
                ),
            };
            text::ServerRow {
                progid,
                versions,
                description,
                clsid,
            }
        })
        .collect();
    match &browser {
        Ok(_) => println!("OPC servers (through OPC.ServerList.1): {}", rows.len()),
        Err(e) => println!(
            "OPC servers (no server browser: {}; through the component categories, \
             this process's registry view only): {}",
            text::hresult_text(e.code().0, None),
            rows.len()
        ),
    }
    print!("{}", text::servers_table(&rows));
    Ok(EXIT_OK)
}

/// The local time zone offset at `t` (0 when Windows cannot tell).
pub fn offset(t: Timestamp) -> i32 {
    diag::utc_offset_minutes(t).unwrap_or(0)
}

/// The system's message for an HRESULT (FormatMessage), if it has one.
fn system_text(hr: HRESULT) -> Option<String> {
    let m = hr.message();
    (!m.trim().is_empty()).then_some(m)
}

impl Session {
    pub fn connect(g: &Global) -> Result<Session, String> {
        let com = Apartment::mta().map_err(|e| {
            format!(
                "cannot initialise COM: {}",
                text::hresult_text(e.code().0, system_text(e.code()).as_deref())
            )
        })?;
        let server = Server::connect(&g.server).map_err(|e| {
            let hr = e.code();
            let hint = match hr.0 as u32 {
                0x8004_01F3 | 0x8004_0154 => {
                    "\n  no server is registered under this ProgID (ServerCTOPC: run `ServerCTOPC.exe /RegServer` as administrator)"
                }
                0x8000_4002 => "\n  the object is not an OPC DA server, or the OPC proxy/stub DLL is not registered (`regsvr32 opc_ps.dll`)",
                0x8008_0005 => "\n  the server process failed to start: see its log",
                _ => "",
            };
            format!("cannot connect to {}: {}{hint}", g.server, text::hresult_text(hr.0, system_text(hr).as_deref()))
        })?;
        let s = Session {
            server,
            progid: g.server.clone(),
            _com: com,
        };
        // Only for the server's log: a server that does not support it still works.
        let _ = s.server.set_client_name("opcdiag");
        if let Some(lcid) = g.lcid {
            s.server.set_locale(lcid).map_err(|e| {
                format!(
                    "the server does not support the language 0x{lcid:04X}: {}",
                    s.error_text(e.code())
                )
            })?;
        }
        Ok(s)
    }

    /// An HRESULT with the server's text for it (GetErrorString), else the system's.
    pub fn error_text(&self, hr: HRESULT) -> String {
        let server = self
            .server
            .error_string(hr)
            .ok()
            .flatten()
            .filter(|t| !t.trim().is_empty());
        text::hresult_text(hr.0, server.or_else(|| system_text(hr)).as_deref())
    }

    fn failed(&self, what: &str, e: windows::core::Error) -> String {
        format!("{what}: {}", self.error_text(e.code()))
    }

    // ---- status ------------------------------------------------------------------------

    pub fn status(&self) -> Result<(), String> {
        let st = self
            .server
            .status()
            .map_err(|e| self.failed("IOPCServer::GetStatus failed", e))?;
        let t = |ts: Timestamp| text::local_iso(ts, offset(ts));
        say!("Server        {}", self.progid);
        say!(
            "Vendor        {}",
            st.vendor_info.as_deref().unwrap_or("(none)")
        );
        say!(
            "Version       {}.{}.{}",
            st.version.0,
            st.version.1,
            st.version.2
        );
        say!(
            "State         {} ({})",
            text::state_name(st.state),
            text::state_meaning(st.state)
        );
        say!("Start time    {}", t(st.start_time));
        say!("Current time  {}", t(st.current_time));
        say!("Last update   {}", t(st.last_update_time));
        say!("Groups        {}", st.group_count);
        let bw = if st.band_width == u32::MAX {
            "unknown".to_string()
        } else {
            format!("{} %", st.band_width)
        };
        say!("Band width    {bw}");
        Ok(())
    }

    // ---- browse ------------------------------------------------------------------------

    fn browse_names(&self, kind: OPCBROWSETYPE) -> Result<Vec<String>, String> {
        self.server
            .browse_item_ids(kind, "", 0, 0)
            .map(|(_, v)| v)
            .map_err(|e| self.failed("BrowseOPCItemIDs failed", e))
    }

    /// Moves the browse position to `path`: a branch item ID (TO), else its names from
    /// the root (DOWN step by step).
    fn go_to_branch(&self, path: &str) -> Result<(), String> {
        if self
            .server
            .change_browse_position(OPC_BROWSE_TO, path)
            .is_ok()
        {
            return Ok(());
        }
        self.server
            .change_browse_position(OPC_BROWSE_TO, "")
            .map_err(|e| self.failed("ChangeBrowsePosition(TO root) failed", e))?;
        for step in text::branch_steps(path) {
            self.server
                .change_browse_position(OPC_BROWSE_DOWN, &step)
                .map_err(|e| {
                    self.failed(
                        &format!("branch {path:?} not found (no branch {step:?})"),
                        e,
                    )
                })?;
        }
        Ok(())
    }

    /// The tree below the current browse position, `max_depth` levels deep: through
    /// IOPCBrowse::Browse (one call per branch, continuation points) when the server
    /// offers it, else IOPCBrowseServerAddressSpace.
    pub fn tree(
        &self,
        depth: usize,
        max_depth: Option<usize>,
        out: &mut Vec<TreeLine>,
    ) -> Result<(), String> {
        let mut progress = Progress::new("elements");
        if self.use_iopcbrowse() {
            let here = self
                .server
                .get_item_id("")
                .map_err(|e| self.failed("GetItemID(\"\") failed", e))?
                .unwrap_or_default();
            self.tree3(&here, depth, max_depth, out, &mut progress)?;
        } else {
            self.tree2(depth, max_depth, out, &mut progress)?;
        }
        progress.done();
        Ok(())
    }

    /// Whether to browse the tree with IOPCBrowse: the server has it, and the environment
    /// variable `OPCDIAG_BROWSE_DA2` (a test hook: the DA 2.05a path on a DA 3.0 server)
    /// is not `1`.
    fn use_iopcbrowse(&self) -> bool {
        std::env::var("OPCDIAG_BROWSE_DA2").as_deref() != Ok("1")
            && self.server.browse_itf().is_ok()
    }

    /// Every element of `item_id` through IOPCBrowse::Browse, BROWSE_BATCH a call,
    /// following continuation points.
    fn browse_all(
        &self,
        item_id: &str,
        progress: &mut Progress,
    ) -> windows::core::Result<Vec<client::BrowseElement>> {
        let mut out = Vec::new();
        let mut cp: Option<String> = None;
        loop {
            let page = self.server.browse(&client::BrowseArgs {
                item_id: item_id.into(),
                continuation_point: cp.take(),
                max_elements: BROWSE_BATCH,
                filter: OPC_BROWSE_FILTER_ALL.0,
                ..Default::default()
            })?;
            progress.add(page.elements.len());
            out.extend(page.elements);
            match page.continuation_point {
                Some(c) if !c.is_empty() => cp = Some(c),
                _ => {
                    if page.more_elements {
                        eprintln!(
                            "opcdiag: {item_id:?}: the server has more elements than it \
                             returned and no continuation point: the listing is incomplete"
                        );
                    }
                    return Ok(out);
                }
            }
        }
    }

    /// [`Session::tree`] through IOPCBrowse, below the branch `item_id`.
    fn tree3(
        &self,
        item_id: &str,
        depth: usize,
        max_depth: Option<usize>,
        out: &mut Vec<TreeLine>,
        progress: &mut Progress,
    ) -> Result<(), String> {
        let elements = match self.browse_all(item_id, progress) {
            Ok(e) => e,
            // A branch that went away since its parent was listed (a client's branch of
            // `_Diagnostics` whose client left): shown without children.
            Err(e) if depth > 0 && e.code() == OPC_E_UNKNOWNITEMID => Vec::new(),
            Err(e) => {
                return Err(self.failed(&format!("IOPCBrowse::Browse({item_id:?}) failed"), e))
            }
        };
        let (branches, leaves): (Vec<_>, Vec<_>) = elements
            .into_iter()
            .partition(|e| e.flags & OPC_BROWSE_HASCHILDREN != 0);
        for b in branches {
            out.push(TreeLine {
                depth,
                name: b.name.unwrap_or_default(),
                item_id: None,
                branch: true,
            });
            // A branch without an item ID cannot be browsed into ("" is the root).
            let id = b.item_id.filter(|id| !id.is_empty());
            if let Some(id) = id.filter(|_| !matches!(max_depth, Some(m) if depth + 1 >= m)) {
                self.tree3(&id, depth + 1, max_depth, out, progress)?;
            }
        }
        for leaf in leaves {
            out.push(TreeLine {
                depth,
                name: leaf.name.unwrap_or_default(),
                item_id: leaf.item_id,
                branch: false,
            });
        }
        Ok(())
    }

    /// [`Session::tree`] through IOPCBrowseServerAddressSpace, below the current position.
    fn tree2(
        &self,
        depth: usize,
        max_depth: Option<usize>,
        out: &mut Vec<TreeLine>,
        progress: &mut Progress,
    ) -> Result<(), String> {
        let branches = self.browse_names(OPC_BRANCH)?;
        progress.add(branches.len());
        for b in branches {
            out.push(TreeLine {
                depth,
                name: b.clone(),
                item_id: None,
                branch: true,
            });
            if !matches!(max_depth, Some(m) if depth + 1 >= m) {
                match self.server.change_browse_position(OPC_BROWSE_DOWN, &b) {
                    Ok(()) => {}
                    // Gone since it was listed (as in `tree3`): shown without children.
                    Err(e) if e.code() == windows::Win32::Foundation::E_INVALIDARG => continue,
                    Err(e) => {
                        return Err(
                            self.failed(&format!("ChangeBrowsePosition(DOWN {b:?}) failed"), e)
                        )
                    }
                }
                let r = self.tree2(depth + 1, max_depth, out, progress);
                self.server
                    .change_browse_position(OPC_BROWSE_UP, "")
                    .map_err(|e| self.failed("ChangeBrowsePosition(UP) failed", e))?;
                r?;
            }
        }
        let leaves = self.browse_names(OPC_LEAF)?;
        progress.add(leaves.len());
        for leaf in leaves {
            // DA 2.05a has no other way to a leaf's item ID (one call per leaf).
            let item_id = self.server.get_item_id(&leaf).ok().flatten();
            out.push(TreeLine {
                depth,
                name: leaf,
                item_id,
                branch: false,
            });
        }
        Ok(())
    }

    pub fn browse(
        &self,
        flat: bool,
        branch: Option<&str>,
        depth: Option<usize>,
    ) -> Result<u8, String> {
        let org = self.server.query_organization().map_err(|e| {
            self.failed(
                "the server does not support browsing (IOPCBrowseServerAddressSpace)",
                e,
            )
        })?;
        let hierarchical = org == OPC_NS_HIERARCHIAL;
        if let Some(path) = branch {
            if !hierarchical {
                return Err("--branch: the server's address space is flat".into());
            }
            self.go_to_branch(path)?;
        }
        if flat || !hierarchical {
            // Printed as the batches arrive: a long listing needs no memory of its own.
            let mut progress = Progress::new("item IDs");
            let _s_ok_or_s_false = self
                .server
                .browse_item_ids_each(OPC_FLAT, "", 0, 0, |batch| {
                    progress.add(batch.len());
                    let size = batch.iter().map(|s| s.len() + 1).sum();
                    let mut block = String::with_capacity(size);
                    for id in &batch {
                        block.push_str(id);
                        block.push('\n');
                    }
                    crate::out::text(&block);
                })
                .map_err(|e| self.failed("BrowseOPCItemIDs failed", e))?;
            progress.done();
            return Ok(EXIT_OK);
        }
        let mut lines = Vec::new();
        self.tree(0, depth, &mut lines)?;
        if lines.is_empty() {
            say!("(empty)");
        }
        crate::out::text(&text::render_tree(&lines));
        Ok(EXIT_OK)
    }

    // ---- props -------------------------------------------------------------------------

    pub fn props(&self, item: &str) -> Result<u8, String> {
        let available = self
            .server
            .query_available_properties(item)
            .map_err(|e| self.failed(&format!("{item}: QueryAvailableProperties failed"), e))?;
        let ids: Vec<u32> = available.iter().map(|p| p.0).collect();
        let (_, values) = self
            .server
            .get_item_properties(item, &ids)
            .map_err(|e| self.failed(&format!("{item}: GetItemProperties failed"), e))?;
        say!("Properties of {item}:");
        say!(
            "{:>5}  {}  {}  Value",
            "ID",
            text::pad("Description", 32),
            text::pad("Type", 6)
        );
        let mut code = EXIT_OK;
        for ((id, desc, vt), (value, err)) in available.iter().zip(values) {
            let shown = if err.is_err() {
                code = EXIT_FAILED;
                format!("error {}", self.error_text(err))
            } else {
                text::property_value_text(*id, &value)
            };
            say!(
                "{id:>5}  {}  {}  {shown}",
                text::pad(desc.as_deref().unwrap_or(""), 32),
                text::pad(&text::vartype_name(*vt), 6)
            );
        }
        Ok(code)
    }

    // ---- groups ------------------------------------------------------------------------

    /// A new private group with `items` added (client handle = index + 1).
    fn group_with(
        &self,
        items: &[String],
        path: &str,
        active: bool,
        rate_ms: u32,
    ) -> Result<TempGroup, String> {
        let spec = GroupSpec {
            name: format!("opcdiag-{}", std::process::id()),
            active,
            rate_ms,
            client_handle: 1,
            time_bias: None,
            deadband: None,
            lcid: 0x0409,
        };
        let added = self
            .server
            .add_group(&spec)
            .map_err(|e| self.failed("IOPCServer::AddGroup failed", e))?;
        let mut group = TempGroup {
            handle: added.server_handle,
            revised_rate: added.revised_rate,
            group: None,
            outcomes: Vec::new(),
        };
        let g = match OpcGroup::from_unknown(added.object) {
            Ok(g) => g,
            Err(e) => {
                group.remove(self);
                return Err(self.failed("the group lacks IOPCItemMgt", e));
            }
        };
        let defs: Vec<ItemDef> = items
            .iter()
            .enumerate()
            .map(|(i, id)| ItemDef {
                item_id: id.clone(),
                access_path: path.to_string(),
                active: true,
                client_handle: i as u32 + 1,
                requested_type: 0,
            })
            .collect();
        let result = g.add_items(&defs);
        group.group = Some(g);
        match result {
            Ok((_, outcomes)) => {
                group.outcomes = outcomes;
                Ok(group)
            }
            Err(e) => {
                let msg = self.failed("IOPCItemMgt::AddItems failed", e);
                group.remove(self);
                Err(msg)
            }
        }
    }

    // ---- read --------------------------------------------------------------------------

    pub fn read(&self, items: &[String], device: bool, path: &str) -> Result<u8, String> {
        let g = self.group_with(items, path, true, 1000)?;
        let r = self.read_in(&g, items, device);
        g.remove(self);
        r
    }

    /// Reads one item from the cache (waiting up to 3 s for its first value), printing
    /// nothing: `opcdiag doctor`'s read.
    pub fn read_one(&self, item: &str) -> Result<ReadItem, String> {
        let items = [item.to_owned()];
        let g = self.group_with(&items, "", true, 1000)?;
        let r = self.read_one_in(&g);
        g.remove(self);
        r
    }

    fn read_one_in(&self, g: &TempGroup) -> Result<ReadItem, String> {
        let outcome = g.outcomes.first().ok_or("AddItems gave no result")?;
        if outcome.error.is_err() {
            return Err(format!("AddItems: {}", self.error_text(outcome.error)));
        }
        let io: IOPCSyncIO = g
            .unknown()?
            .cast()
            .map_err(|e| self.failed("the group lacks IOPCSyncIO", e))?;
        let deadline = Instant::now() + Duration::from_secs(3);
        loop {
            let (_, read) = client::sync_read(&io, OPC_DS_CACHE, &[outcome.server_handle])
                .map_err(|e| self.failed("IOPCSyncIO::Read failed", e))?;
            let r = read.into_iter().next().ok_or("Read gave no result")?;
            if r.error.is_err() {
                return Err(format!("Read: {}", self.error_text(r.error)));
            }
            if r.quality != ctopc_core::Quality::BAD_WAITING_FOR_INITIAL_DATA.0
                || Instant::now() >= deadline
            {
                return Ok(r);
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    fn read_in(&self, g: &TempGroup, items: &[String], device: bool) -> Result<u8, String> {
        let mut code = EXIT_OK;
        let width = items.iter().map(|i| i.chars().count()).max().unwrap_or(0);
        let ok: Vec<(usize, u32)> = g
            .outcomes
            .iter()
            .enumerate()
            .filter(|(_, o)| o.error.is_ok())
            .map(|(i, o)| (i, o.server_handle))
            .collect();
        let mut results: Vec<Option<ReadItem>> = vec![None; items.len()];
        if !ok.is_empty() {
            let io: IOPCSyncIO = g
                .unknown()?
                .cast()
                .map_err(|e| self.failed("the group lacks IOPCSyncIO", e))?;
            let handles: Vec<u32> = ok.iter().map(|x| x.1).collect();
            let source = if device { OPC_DS_DEVICE } else { OPC_DS_CACHE };
            // A cache read right after AddItems may come before the first value: wait for it.
            let deadline = Instant::now() + Duration::from_secs(3);
            loop {
                let (_, read) = client::sync_read(&io, source, &handles)
                    .map_err(|e| self.failed("IOPCSyncIO::Read failed", e))?;
                let waiting = read.iter().any(|r| {
                    r.error.is_ok()
                        && r.quality == ctopc_core::Quality::BAD_WAITING_FOR_INITIAL_DATA.0
                });
                for ((i, _), r) in ok.iter().zip(read) {
                    results[*i] = Some(r);
                }
                if !waiting || Instant::now() >= deadline {
                    break;
                }
                std::thread::sleep(Duration::from_millis(100));
            }
        }
        for (i, item) in items.iter().enumerate() {
            let name = text::pad(item, width);
            let add_error = g.outcomes.get(i).map(|o| o.error).unwrap_or(HRESULT(0));
            if add_error.is_err() {
                code = EXIT_FAILED;
                say!("{name}  error {}", self.error_text(add_error));
                continue;
            }
            match &results[i] {
                Some(r) if r.error.is_err() => {
                    code = EXIT_FAILED;
                    say!("{name}  error {}", self.error_text(r.error));
                }
                Some(r) => say!(
                    "{name}  {}  {}  {}  {}",
                    text::value_text(&r.value),
                    text::vartype_name(r.vt),
                    text::quality_text(r.quality),
                    text::local_iso(r.timestamp, offset(r.timestamp))
                ),
                None => {
                    code = EXIT_FAILED;
                    say!("{name}  error: no result");
                }
            }
        }
        Ok(code)
    }

    // ---- write -------------------------------------------------------------------------

    pub fn write(
        &self,
        item: &str,
        value: &str,
        vt: Option<VarType>,
        path: &str,
    ) -> Result<u8, String> {
        let g = self.group_with(&[item.to_string()], path, false, 1000)?;
        let r = self.write_in(&g, item, value, vt);
        g.remove(self);
        r
    }

    fn write_in(
        &self,
        g: &TempGroup,
        item: &str,
        value: &str,
        vt: Option<VarType>,
    ) -> Result<u8, String> {
        let Some(outcome) = g.outcomes.first() else {
            return Err(format!("{item}: AddItems returned no result"));
        };
        if outcome.error.is_err() {
            say!(
                "{item}: cannot add the item: {}",
                self.error_text(outcome.error)
            );
            return Ok(EXIT_FAILED);
        }
        let target = vt.unwrap_or(VarType(outcome.canonical_type));
        let v = match text::parse_value(value, target) {
            Ok(v) => v,
            Err(e) => {
                eprintln!("opcdiag: {item}: {e}");
                return Ok(EXIT_USAGE);
            }
        };
        let io: IOPCSyncIO = g
            .unknown()?
            .cast()
            .map_err(|e| self.failed("the group lacks IOPCSyncIO", e))?;
        let (_, errors) = client::sync_write(&io, &[(outcome.server_handle, v.clone())])
            .map_err(|e| self.failed("IOPCSyncIO::Write failed", e))?;
        let result = errors.first().copied().unwrap_or(HRESULT(0));
        let shown = format!(
            "{} ({})",
            text::value_text(&v),
            text::vartype_name(v.var_type().0)
        );
        if result.is_err() {
            say!("{item}: write {shown} failed: {}", self.error_text(result));
            Ok(EXIT_FAILED)
        } else if result != HRESULT(0) {
            say!("{item}: written {shown}: {}", self.error_text(result));
            Ok(EXIT_OK)
        } else {
            say!("{item}: written {shown}: OK");
            Ok(EXIT_OK)
        }
    }

    // ---- subscribe ---------------------------------------------------------------------

    pub fn subscribe(
        &self,
        items: &[String],
        rate_ms: u32,
        for_secs: Option<f64>,
        count: Option<usize>,
        path: &str,
    ) -> Result<u8, String> {
        let sub = Subscription::start(self, items, path, rate_ms)?;
        let mut code = EXIT_OK;
        for (name, err) in &sub.failed {
            code = EXIT_FAILED;
            say!("{name}  error {}", self.error_text(*err));
        }
        let width = items.iter().map(|i| i.chars().count()).max().unwrap_or(0);
        let until = match (for_secs, count) {
            (Some(s), Some(c)) => format!("for {c} change(s) or {s} s"),
            (None, Some(c)) => format!("for {c} change(s)"),
            (Some(s), None) => format!("for {s} s"),
            (None, None) => "until Ctrl+C".into(),
        };
        let rate = if sub.revised_rate == rate_ms {
            format!("{rate_ms} ms")
        } else {
            format!("{} ms (asked for {rate_ms})", sub.revised_rate)
        };
        say!(
            "Subscribed to {} item(s), update rate {rate}, {until}:",
            sub.names.len() - sub.failed.len()
        );
        let started = Instant::now();
        let n = sub.run(for_secs, count, |name, r| {
            let value = if r.error.is_err() {
                format!("error {}", self.error_text(r.error))
            } else {
                text::value_text(&r.value)
            };
            say!(
                "{}  {}  {}  {}",
                text::local_time_of_day(r.timestamp, offset(r.timestamp)),
                text::pad(name, width),
                value,
                text::quality_text(r.quality)
            );
        });
        sub.stop(self);
        say!("{n} change(s) in {:.1} s", started.elapsed().as_secs_f64());
        Ok(count_reached(code, n, count))
    }
}

/// `subscribe --count N`: fewer than N changes (the time ran out) is a failure.
fn count_reached(code: u8, n: usize, count: Option<usize>) -> u8 {
    match count {
        Some(c) if n < c => {
            say!("opcdiag: {n} of the {c} change(s) asked for with --count arrived");
            EXIT_FAILED
        }
        _ => code,
    }
}

/// A group opcdiag made; removed with [`TempGroup::remove`].
pub struct TempGroup {
    pub handle: u32,
    pub revised_rate: u32,
    group: Option<OpcGroup>,
    /// One AddItems result per requested item.
    pub outcomes: Vec<client::ItemOutcome>,
}

impl TempGroup {
    fn unknown(&self) -> Result<&windows::core::IUnknown, String> {
        self.group
            .as_ref()
            .map(|g| &g.unknown)
            .ok_or_else(|| "the group is gone".to_string())
    }

    /// Releases the group's interfaces, then removes it from the server.
    pub fn remove(mut self, s: &Session) {
        self.group = None;
        let _ = s.server.remove_group(self.handle, true);
    }
}

/// An active group with an IOPCDataCallback sink.
pub struct Subscription {
    group: TempGroup,
    cookie: u32,
    /// Every callback of the sink (only OnDataChange comes: the group has no other I/O).
    rx: Receiver<Callback>,
    /// The requested item IDs (client handle = index + 1).
    pub names: Vec<String>,
    /// Items AddItems refused, with the reason.
    pub failed: Vec<(String, HRESULT)>,
    pub revised_rate: u32,
}

impl Subscription {
    pub fn start(
        s: &Session,
        items: &[String],
        path: &str,
        rate_ms: u32,
    ) -> Result<Subscription, String> {
        let group = s.group_with(items, path, true, rate_ms)?;
        let failed: Vec<(String, HRESULT)> = items
            .iter()
            .zip(&group.outcomes)
            .filter(|(_, o)| o.error.is_err())
            .map(|(n, o)| (n.clone(), o.error))
            .collect();
        if failed.len() == items.len() {
            let reasons: Vec<String> = failed
                .iter()
                .map(|(n, e)| format!("  {n}: {}", s.error_text(*e)))
                .collect();
            group.remove(s);
            return Err(format!("no item could be added:\n{}", reasons.join("\n")));
        }
        let (tx, rx) = mpsc::channel();
        let sink = Recording::with(Options {
            count_only: true,
            forward: Some(tx),
            ..Options::default()
        })
        .sink();
        let cookie = match group.unknown().and_then(|u| {
            client::advise_data_callback(u, &sink)
                .map_err(|e| s.failed("IOPCDataCallback Advise failed", e))
        }) {
            Ok(c) => c,
            Err(e) => {
                group.remove(s);
                return Err(e);
            }
        };
        // Ctrl+C now ends the loop instead of the process (which would leave the group
        // and its callback connection behind in the server).
        let _ = diag::catch_ctrl_c();
        let revised_rate = group.revised_rate;
        Ok(Subscription {
            group,
            cookie,
            rx,
            names: items.to_vec(),
            failed,
            revised_rate,
        })
    }

    /// Calls `each(item, value)` for every item of every OnDataChange until Ctrl+C,
    /// `for_secs` or `count` item changes; returns the number of item changes.
    pub fn run(
        &self,
        for_secs: Option<f64>,
        count: Option<usize>,
        mut each: impl FnMut(&str, &ReadItem),
    ) -> usize {
        let deadline = for_secs.map(|s| Instant::now() + Duration::from_secs_f64(s));
        let mut n = 0;
        loop {
            if diag::ctrl_c_pressed() || crate::out::closed() || count.is_some_and(|c| n >= c) {
                break;
            }
            let wait = match deadline {
                Some(d) => {
                    let left = d.saturating_duration_since(Instant::now());
                    if left.is_zero() {
                        break;
                    }
                    left.min(Duration::from_millis(200))
                }
                None => Duration::from_millis(200),
            };
            match self.rx.recv_timeout(wait) {
                Ok(Callback::DataChange { items, .. }) => {
                    for item in &items {
                        let name = self
                            .names
                            .get((item.client_handle as usize).wrapping_sub(1))
                            .map_or("?", String::as_str);
                        each(name, item);
                        n += 1;
                    }
                }
                Ok(_) | Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => break,
            }
        }
        n
    }

    /// The items of the first OnDataChange within `timeout`, if one came.
    pub fn first(&self, timeout: Duration) -> Option<Vec<ReadItem>> {
        let deadline = Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.rx.recv_timeout(left) {
                Ok(Callback::DataChange { items, .. }) => return Some(items),
                Ok(_) => {}
                Err(_) => return None,
            }
        }
    }

    /// Disconnects the sink and removes the group.
    pub fn stop(self, s: &Session) {
        if let Ok(u) = self.group.unknown() {
            let _ = client::unadvise_data_callback(u, self.cookie);
        }
        self.group.remove(s);
    }
}
