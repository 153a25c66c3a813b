//! The node manager of our namespace (async-opcua's [`NodeManager`]): Browse and
//! BrowseNext, TranslateBrowsePaths (through browse), Read, Write and monitored items,
//! each answered from the lazy address space ([`crate::space`]) and the engine
//! ([`crate::engine`], [`crate::monitor`]).
//!
//! Calls that may wait for the data source (a Value read with MaxAge 0 or a stale cache,
//! every write) run on tokio's blocking pool, never on the runtime's worker threads.

use crate::engine::EngineClient;
use crate::monitor::{state_to_data_value, Monitor};
use crate::space::{Meta, Resolved, Space, NAMESPACE_URI};
use crate::status::error_to_status;
use crate::value::{from_variant, timestamp_from_ua};
use ctopc_core::browse::AddressSpace;
use ctopc_core::lang::Lang;
use ctopc_core::model::{ItemVqt, MAX_AGE_CACHE};
use ctopc_core::namespace::{Namespace, OPC_WRITEABLE};
use ctopc_core::write_rights::Caller;
use ctopc_core::OpcError;
use opcua::nodes::{DefaultTypeTree, ReferenceDirection};
use opcua::server::authenticator::UserToken;
use opcua::server::diagnostics::NamespaceMetadata;
use opcua::server::node_manager::{
    impl_translate_browse_paths_using_browse, AddReferenceResult, BrowseNode, BrowsePathItem,
    DynNodeManager, ExternalReference, ExternalReferenceRequest, MonitoredItemRef,
    MonitoredItemUpdateRef, NodeManager, NodeManagerBuilder, NodeMetadata, ReadNode,
    RequestContext, ServerContext, WriteNode,
};
use opcua::server::{CreateMonitoredItem, MonitoredItemHandle};
use opcua::types::{
    AttributeId, DataValue, ExpandedNodeId, IdType, NodeId, NumericRange, ObjectId,
    ReferenceDescription, ReferenceTypeId, StatusCode, TimestampsToReturn,
};
use std::collections::{HashMap, VecDeque};
use std::sync::{Arc, Mutex};

/// Who may write: the user a session authenticated as.
pub trait Roles: Send + Sync {
    /// True when `token`'s user may write variables.
    fn may_write(&self, token: &UserToken) -> bool;

    /// The roles of `token`'s user, for the write-rights policy (`role:NAME`).
    fn roles(&self, token: &UserToken) -> Vec<String> {
        vec![if self.may_write(token) {
            "writer"
        } else {
            "reader"
        }
        .to_owned()]
    }
}

/// Everyone may write (in-process tests).
pub struct AllWrite;

impl Roles for AllWrite {
    fn may_write(&self, _token: &UserToken) -> bool {
        true
    }
}

/// What the node manager serves: the namespace, its browse tree, the engine session and
/// the write rights.
pub struct Setup {
    pub namespace: Arc<dyn Namespace>,
    pub tree: Arc<AddressSpace>,
    pub engine: Arc<EngineClient>,
    pub roles: Arc<dyn Roles>,
    /// The server's default language: the texts' language for a session whose LocaleIds
    /// name neither Polish nor English (see [`AsixNodeManager::session_lang`]).
    pub lang: Lang,
}

/// Builds the node manager when the server is built (it learns its namespace index and
/// the subscription cache then).
pub struct AsixNodeManagerBuilder {
    setup: Setup,
    limits: crate::limits::Limits,
    /// Where the built node manager is handed back (the server keeps it for its tests
    /// and its shutdown).
    out: Arc<Mutex<Option<Arc<AsixNodeManager>>>>,
}

impl AsixNodeManagerBuilder {
    pub fn new(setup: Setup) -> (Self, Arc<Mutex<Option<Arc<AsixNodeManager>>>>) {
        let out = Arc::new(Mutex::new(None));
        (
            AsixNodeManagerBuilder {
                setup,
                limits: crate::limits::Limits::default(),
                out: Arc::clone(&out),
            },
            out,
        )
    }

    /// The limits the node manager counts (monitored items in all, the request rate).
    pub fn limits(mut self, limits: &crate::limits::Limits) -> Self {
        self.limits = limits.clone();
        self
    }
}

impl NodeManagerBuilder for AsixNodeManagerBuilder {
    fn build(self: Box<Self>, context: ServerContext) -> Arc<DynNodeManager> {
        let ns = context
            .type_tree
            .write()
            .namespaces_mut()
            .add_namespace(NAMESPACE_URI);
        let notify = Arc::clone(&context.subscriptions) as Arc<dyn crate::monitor::Notify>;
        let mut nm = AsixNodeManager::new(self.setup, ns, notify);
        nm.budget = crate::limits::ItemBudget::new(self.limits.max_monitored_items);
        nm.rate = crate::limits::RateLimiter::new(
            self.limits.max_requests_per_second,
            self.limits.max_sessions,
        );
        let nm = Arc::new(nm);
        *self.out.lock().unwrap_or_else(|p| p.into_inner()) = Some(Arc::clone(&nm));
        nm
    }
}

/// The rest of a browse result that did not fit (already filtered).
struct BrowseRest {
    refs: VecDeque<ReferenceDescription>,
}

/// The node manager of the `urn:askom:ServerCTOPC` namespace.
pub struct AsixNodeManager {
    pub space: Arc<Space>,
    pub engine: Arc<EngineClient>,
    pub monitor: Arc<Monitor>,
    roles: Arc<dyn Roles>,
    /// The server's default language.
    lang: Lang,
    /// The Value monitored items: their item ID and engine rate.
    items: Mutex<HashMap<MonitoredItemHandle, (String, u32)>>,
    /// `MaxMonitoredItems`, over the Value monitored items.
    budget: crate::limits::ItemBudget,
    /// `MaxRequestsPerSecond`, over the requests reaching this node manager.
    rate: crate::limits::RateLimiter,
}

fn to_description(m: Meta, reference_type: NodeId, forward: bool) -> ReferenceDescription {
    ReferenceDescription {
        reference_type_id: reference_type,
        is_forward: forward,
        node_id: m.node_id.into(),
        browse_name: m.browse_name,
        display_name: m.display_name,
        node_class: m.node_class,
        type_definition: if m.type_definition.is_null() {
            ExpandedNodeId::null()
        } else {
            m.type_definition.into()
        },
    }
}

/// MaxAge of a UA Read (ms, a double) as the engine's (0: the device; very large: the cache).
pub fn max_age_ms(max_age: f64) -> u32 {
    if !max_age.is_finite() || max_age >= f64::from(i32::MAX) {
        MAX_AGE_CACHE
    } else if max_age <= 0.0 {
        0
    } else {
        (max_age as u32).max(1)
    }
}

impl AsixNodeManager {
    /// The node manager of namespace index `ns`, its data changes going to `notify`.
    pub fn new(setup: Setup, ns: u16, notify: Arc<dyn crate::monitor::Notify>) -> Self {
        let scan_rate_ms = setup
            .engine
            .runtime
            .lock()
            .engine
            .config()
            .min_update_rate_ms;
        let diag = Arc::clone(&setup.engine.runtime.diagnostics);
        let monitor = Monitor::new(ns, Arc::clone(&setup.engine));
        monitor.set_subscriptions(notify);
        AsixNodeManager {
            space: Arc::new(Space {
                ns,
                namespace: setup.namespace,
                tree: setup.tree,
                scan_rate_ms,
                diag,
            }),
            engine: setup.engine,
            monitor,
            roles: setup.roles,
            lang: setup.lang,
            items: Mutex::new(HashMap::new()),
            budget: crate::limits::ItemBudget::new(
                crate::limits::Limits::default().max_monitored_items,
            ),
            rate: crate::limits::RateLimiter::new(0, 1),
        }
    }

    /// One request of the context's session against `MaxRequestsPerSecond`.
    fn admit(&self, context: &RequestContext) -> Result<(), StatusCode> {
        self.rate
            .admit(context.session_id, std::time::Instant::now())
    }

    /// The language of the texts (Description, the DisplayNames that have a language)
    /// for the context's session: the first of its LocaleIds (ActivateSession) that names
    /// Polish or English, else the server's default.
    pub fn session_lang(&self, context: &RequestContext) -> Lang {
        let session = context.session().read();
        let ids = session.locale_ids().unwrap_or_default();
        Lang::from_locale_ids(ids.iter().map(|id| id.as_ref()), self.lang)
    }

    fn items(&self) -> std::sync::MutexGuard<'_, HashMap<MonitoredItemHandle, (String, u32)>> {
        self.items.lock().unwrap_or_else(|p| p.into_inner())
    }

    fn browse_one(&self, node: &mut BrowseNode, type_tree: &DefaultTypeTree, lang: Lang) {
        let mut rest = VecDeque::new();
        if let Some(cp) = node.take_continuation_point::<BrowseRest>() {
            for r in cp.refs {
                if node.remaining() > 0 {
                    node.add_unchecked(r);
                } else {
                    rest.push_back(r);
                }
            }
            node.set_status(StatusCode::Good);
        } else if node.node_id().namespace == 0
            && node.node_id().as_u32() == Some(ObjectId::ObjectsFolder as u32)
        {
            // The Objects folder (the core's) organizes our folder.
            let r = to_description(
                self.space.root_meta(),
                ReferenceTypeId::Organizes.into(),
                true,
            );
            if let AddReferenceResult::Full(r) = node.add(type_tree, r) {
                rest.push_back(r);
            }
        } else if self.owns_node(node.node_id()) {
            match self.space.resolve(node.node_id()) {
                Err(e) => node.set_status(e),
                Ok(resolved) => {
                    for r in self.space.references(&resolved, lang) {
                        let direction_ok = if r.forward {
                            node.allows_forward()
                        } else {
                            node.allows_inverse()
                        };
                        if !direction_ok {
                            continue;
                        }
                        if r.target.node_id.namespace == 0 {
                            let direction = if r.forward {
                                ReferenceDirection::Forward
                            } else {
                                ReferenceDirection::Inverse
                            };
                            if node.allows_reference_type(&r.reference_type, type_tree) {
                                node.push_external_reference(ExternalReference::new(
                                    r.target.node_id.into(),
                                    r.reference_type,
                                    direction,
                                ));
                            }
                            continue;
                        }
                        let d = to_description(r.target, r.reference_type, r.forward);
                        if let AddReferenceResult::Full(d) = node.add(type_tree, d) {
                            rest.push_back(d);
                        }
                    }
                    node.set_status(StatusCode::Good);
                }
            }
        }
        if !rest.is_empty() {
            node.set_next_continuation_point(Box::new(BrowseRest { refs: rest }));
        }
    }

    /// A node's attribute answered from the address space (no engine read: the Value of a
    /// variable is the engine's, so a node that resolves to a variable here is one the
    /// engine did not know, Bad_NodeIdUnknown).
    fn read_attribute(&self, node: &mut ReadNode, may_write: bool, lang: Lang) {
        let (id, attribute) = (&node.node().node_id, node.node().attribute_id);
        match self.space.resolve(id) {
            Err(e) => node.set_error(e),
            Ok(Resolved::Variable(_)) if attribute == AttributeId::Value => {
                node.set_error(StatusCode::BadNodeIdUnknown)
            }
            Ok(r) => match self.space.attribute(&r, attribute, may_write, lang) {
                Ok(v) => node.set_result(DataValue::value_only(v)),
                Err(e) => node.set_error(e),
            },
        }
    }

    /// A monitored item of a node's attribute answered from the address space: its value
    /// is the initial (and only) one (no engine item: the Value of a variable is the
    /// engine's, so a node that resolves to a variable here is one the engine did not
    /// know, Bad_NodeIdUnknown).
    fn monitor_attribute(&self, item: &mut CreateMonitoredItem, may_write: bool, lang: Lang) {
        let target = item.item_to_monitor();
        let attribute = target.attribute_id;
        let answer = match self.space.resolve(&target.node_id) {
            Err(e) => Err(e),
            Ok(Resolved::Variable(_)) if attribute == AttributeId::Value => {
                Err(StatusCode::BadNodeIdUnknown)
            }
            Ok(r) => self.space.attribute(&r, attribute, may_write, lang),
        };
        match answer {
            Ok(v) => {
                item.set_initial_value(DataValue::value_only(v));
                item.set_status(StatusCode::Good);
            }
            Err(e) => item.set_status(e),
        }
    }

    /// Reads the Value of items through the engine (blocking: the caller is on the
    /// blocking pool or a test thread).
    pub fn read_values(&self, items: &[String], max_age: u32) -> Vec<DataValue> {
        let req: Vec<(&str, u32)> = items.iter().map(|s| (s.as_str(), max_age)).collect();
        self.engine
            .read(&req)
            .into_iter()
            .map(|r| match r {
                Ok(s) => state_to_data_value(&s),
                Err(e) => DataValue {
                    status: Some(error_to_status(e, false)),
                    server_timestamp: Some(opcua::types::DateTime::now()),
                    ..DataValue::null()
                },
            })
            .collect()
    }

    /// What a Write of one node comes to before the engine: the item and value to write,
    /// or the node's status. `may_write`: the session's user may write.
    pub fn check_write(
        &self,
        node_id: &NodeId,
        attribute: AttributeId,
        index_range: &NumericRange,
        value: &DataValue,
        may_write: bool,
    ) -> Result<(String, ItemVqt), StatusCode> {
        let resolved = self.space.resolve(node_id)?;
        let Resolved::Variable(info) = resolved else {
            return Err(StatusCode::BadNotWritable);
        };
        if attribute != AttributeId::Value {
            return Err(StatusCode::BadNotWritable);
        }
        if info.def.access_rights & OPC_WRITEABLE == 0 {
            if let Some(why) = self.space.namespace.write_refusal(&info.item_id, "") {
                tracing::warn!("OPC UA: write of {} refused: {why}", info.item_id);
            }
            return Err(StatusCode::BadNotWritable);
        }
        if !may_write {
            return Err(StatusCode::BadUserAccessDenied);
        }
        if !matches!(index_range, NumericRange::None) {
            return Err(StatusCode::BadWriteNotSupported);
        }
        if value.status.is_some_and(|s| !s.is_good()) || value.server_timestamp.is_some() {
            return Err(StatusCode::BadWriteNotSupported);
        }
        let v = match &value.value {
            Some(v) => from_variant(v)?,
            None => return Err(StatusCode::BadTypeMismatch),
        };
        let vqt = ItemVqt {
            value: v,
            quality: None,
            timestamp: value.source_timestamp.as_ref().map(timestamp_from_ua),
        };
        Ok((info.item_id.clone(), vqt))
    }
}

/// Writes values of items through the engine's write conversion (blocking); a write the
/// namespace refuses by design logs why.
pub fn write_values(
    engine: &EngineClient,
    ns: &dyn Namespace,
    items: &[(String, ItemVqt)],
    caller: Caller,
) -> Vec<StatusCode> {
    let req: Vec<(&str, ItemVqt)> = items
        .iter()
        .map(|(id, v)| (id.as_str(), v.clone()))
        .collect();
    let (results, denied) = engine.write(&req, caller);
    results
        .into_iter()
        .zip(items)
        .enumerate()
        .map(|(i, (r, (id, _)))| match r {
            Ok(()) => StatusCode::Good,
            Err(_) if denied.get(i) == Some(&true) => StatusCode::BadUserAccessDenied,
            Err(e) => {
                if e == OpcError::BadRights {
                    if let Some(why) = ns.write_refusal(id, "") {
                        tracing::warn!("OPC UA: write of {id} refused: {why}");
                    }
                }
                error_to_status(e, true)
            }
        })
        .collect()
}

#[async_trait::async_trait]
impl NodeManager for AsixNodeManager {
    fn owns_node(&self, id: &NodeId) -> bool {
        id.namespace == self.space.ns
    }

    fn name(&self) -> &str {
        "ServerCTOPC"
    }

    fn namespaces_for_user(&self, _context: &RequestContext) -> Vec<NamespaceMetadata> {
        vec![NamespaceMetadata {
            is_namespace_subset: Some(false),
            namespace_index: self.space.ns,
            namespace_uri: NAMESPACE_URI.to_owned(),
            static_node_id_types: Some(vec![IdType::Numeric]),
            ..Default::default()
        }]
    }

    async fn init(&self, _type_tree: &mut DefaultTypeTree, _context: ServerContext) {}

    async fn resolve_external_references(
        &self,
        context: &RequestContext,
        items: &mut [&mut ExternalReferenceRequest],
    ) {
        let lang = self.session_lang(context);
        for item in items {
            if let Ok(r) = self.space.resolve(item.node_id()) {
                let m = self.space.meta(&r, lang);
                item.set(NodeMetadata {
                    node_id: m.node_id.into(),
                    type_definition: m.type_definition.into(),
                    browse_name: m.browse_name,
                    display_name: m.display_name,
                    node_class: m.node_class,
                });
            }
        }
    }

    async fn browse(
        &self,
        context: &RequestContext,
        nodes_to_browse: &mut [BrowseNode],
    ) -> Result<(), StatusCode> {
        self.admit(context)?;
        let lang = self.session_lang(context);
        let type_tree = context.type_tree.read();
        for node in nodes_to_browse {
            self.browse_one(node, &type_tree, lang);
        }
        Ok(())
    }

    async fn translate_browse_paths_to_node_ids(
        &self,
        context: &RequestContext,
        nodes: &mut [&mut BrowsePathItem],
    ) -> Result<(), StatusCode> {
        impl_translate_browse_paths_using_browse(self, context, nodes).await
    }

    async fn read(
        &self,
        context: &RequestContext,
        max_age: f64,
        _timestamps_to_return: TimestampsToReturn,
        nodes_to_read: &mut [&mut ReadNode],
    ) -> Result<(), StatusCode> {
        self.admit(context)?;
        let may_write = self.roles.may_write(&context.token);
        let lang = self.session_lang(context);
        // The Value of our items straight from the engine (which resolves each item once);
        // every other attribute, and a node the engine does not know as an item (a folder,
        // nothing), through the address space.
        let mut values: Vec<(usize, String)> = Vec::new();
        for (i, node) in nodes_to_read.iter_mut().enumerate() {
            if node.node().attribute_id == AttributeId::Value {
                if let Some(item) = self.space.value_item(&node.node().node_id) {
                    values.push((i, item));
                    continue;
                }
            }
            self.read_attribute(node, may_write, lang);
        }
        if values.is_empty() {
            return Ok(());
        }
        let ids: Vec<String> = values.iter().map(|(_, id)| id.clone()).collect();
        let age = max_age_ms(max_age);
        let engine = Arc::clone(&self.engine);
        let results = tokio::task::spawn_blocking(move || {
            let req: Vec<(&str, u32)> = ids.iter().map(|s| (s.as_str(), age)).collect();
            engine.read(&req)
        })
        .await
        .map_err(|_| StatusCode::BadInternalError)?;
        for ((i, _), r) in values.iter().zip(results) {
            let node = &mut nodes_to_read[*i];
            match r {
                Ok(s) => node.set_result(state_to_data_value(&s)),
                Err(OpcError::UnknownItemId | OpcError::InvalidItemId) => {
                    self.read_attribute(node, may_write, lang)
                }
                Err(e) => node.set_error(error_to_status(e, false)),
            }
        }
        Ok(())
    }

    async fn write(
        &self,
        context: &RequestContext,
        nodes_to_write: &mut [&mut WriteNode],
    ) -> Result<(), StatusCode> {
        self.admit(context)?;
        let may_write = self.roles.may_write(&context.token);
        let mut writes: Vec<(usize, (String, ItemVqt))> = Vec::new();
        for (i, node) in nodes_to_write.iter_mut().enumerate() {
            let v = node.value();
            match self.check_write(
                &v.node_id,
                v.attribute_id,
                &v.index_range,
                &v.value,
                may_write,
            ) {
                Ok(w) => writes.push((i, w)),
                Err(e) => node.set_status(e),
            }
        }
        if writes.is_empty() {
            return Ok(());
        }
        let items: Vec<(String, ItemVqt)> = writes.iter().map(|(_, w)| w.clone()).collect();
        let caller = Caller::Ua {
            user: context.token.0.clone(),
            roles: self.roles.roles(&context.token),
        };
        let engine = Arc::clone(&self.engine);
        let ns = Arc::clone(&self.space.namespace);
        let statuses =
            tokio::task::spawn_blocking(move || write_values(&engine, &*ns, &items, caller))
                .await
                .map_err(|_| StatusCode::BadInternalError)?;
        for ((i, _), s) in writes.iter().zip(statuses) {
            nodes_to_write[*i].set_status(s);
        }
        Ok(())
    }

    async fn create_monitored_items(
        &self,
        context: &RequestContext,
        items: &mut [&mut CreateMonitoredItem],
    ) -> Result<(), StatusCode> {
        self.admit(context)?;
        let may_write = self.roles.may_write(&context.token);
        let lang = self.session_lang(context);
        // The Value of our items, added to the engine together after the loop (which
        // resolves each item once); every other attribute, and a node the engine does not
        // know as an item, through the address space.
        let mut values: Vec<(usize, String, u32)> = Vec::new();
        for (i, item) in items.iter_mut().enumerate() {
            let target = item.item_to_monitor();
            if target.attribute_id == AttributeId::Value {
                if let Some(item_id) = self.space.value_item(&target.node_id) {
                    if let Err(e) = self.budget.take() {
                        item.set_status(e);
                        continue;
                    }
                    let rate = self.monitor.revise(item.sampling_interval());
                    values.push((i, item_id, rate));
                    continue;
                }
            }
            self.monitor_attribute(item, may_write, lang);
        }
        if values.is_empty() {
            return Ok(());
        }
        // The engine's part on the blocking pool (it waits for the engine's lock, which
        // the driver holds while it handles the source's samples): the variables placed in
        // their groups in one call, then the cached values of those placed in one read.
        // A variable with a cached value (another monitored item or a DA client
        // subscribes it) starts with it; otherwise the first sample comes as a data change.
        let req: Vec<(String, u32)> = values
            .iter()
            .map(|(_, id, rate)| (id.clone(), *rate))
            .collect();
        let monitor = Arc::clone(&self.monitor);
        let engine = Arc::clone(&self.engine);
        let joined = tokio::task::spawn_blocking(move || {
            let ids: Vec<(&str, u32)> = req.iter().map(|(id, r)| (id.as_str(), *r)).collect();
            let added = monitor.add_many(&ids);
            let placed: Vec<(&str, u32)> = ids
                .iter()
                .zip(&added)
                .filter(|(_, r)| r.is_ok())
                .map(|((id, _), _)| (*id, MAX_AGE_CACHE))
                .collect();
            let cached = engine.read(&placed);
            (added, cached)
        })
        .await;
        let Ok((added, cached)) = joined else {
            for _ in &values {
                self.budget.give_back();
            }
            return Err(StatusCode::BadInternalError);
        };
        let mut cached = cached.into_iter();
        for ((i, item_id, rate), r) in values.into_iter().zip(added) {
            let item = &mut items[i];
            match r {
                Ok(()) => {
                    item.revise_sampling_interval(f64::from(rate));
                    self.items().insert(item.handle(), (item_id, rate));
                    item.set_status(StatusCode::Good);
                    if let Some(Ok(s)) = cached.next() {
                        if s.quality != ctopc_core::Quality::BAD_WAITING_FOR_INITIAL_DATA {
                            item.set_initial_value(state_to_data_value(&s));
                        }
                    }
                }
                Err(OpcError::UnknownItemId | OpcError::InvalidItemId) => {
                    self.budget.give_back();
                    self.monitor_attribute(item, may_write, lang);
                }
                Err(e) => {
                    self.budget.give_back();
                    item.set_status(error_to_status(e, false));
                }
            }
        }
        Ok(())
    }

    async fn modify_monitored_items(
        &self,
        _context: &RequestContext,
        items: &[&MonitoredItemUpdateRef],
    ) {
        let mut changes: Vec<(String, u32, u32)> = Vec::new();
        for item in items {
            if !item.status_code().is_good() {
                continue;
            }
            let revised = item.update().revised_sampling_interval;
            let mut map = self.items();
            if let Some((id, rate)) = map.get_mut(&item.handle()) {
                let to = self.monitor.revise(revised);
                let from = std::mem::replace(rate, to);
                changes.push((id.clone(), from, to));
            }
        }
        if changes.is_empty() {
            return;
        }
        // A variable moved to another rate's group: engine calls, on the blocking pool.
        let monitor = Arc::clone(&self.monitor);
        let moved = tokio::task::spawn_blocking(move || {
            for (id, from, to) in changes {
                monitor.change(&id, from, to);
            }
        })
        .await;
        if moved.is_err() {
            tracing::error!("OPC UA: moving monitored items to their new rates' groups failed");
        }
    }

    async fn delete_monitored_items(&self, _context: &RequestContext, items: &[&MonitoredItemRef]) {
        let removed: Vec<(String, u32)> = {
            let mut map = self.items();
            items
                .iter()
                .filter_map(|item| map.remove(&item.handle()))
                .collect()
        };
        for _ in &removed {
            self.budget.give_back();
        }
        if removed.is_empty() {
            return;
        }
        // The engine items of the variables no item monitors any more: engine calls, on
        // the blocking pool.
        let monitor = Arc::clone(&self.monitor);
        let gone = tokio::task::spawn_blocking(move || {
            let req: Vec<(&str, u32)> = removed.iter().map(|(id, r)| (id.as_str(), *r)).collect();
            monitor.remove_many(&req);
        })
        .await;
        if gone.is_err() {
            tracing::error!("OPC UA: removing deleted monitored items from the engine failed");
        }
    }
}
