//! camloop's node manager as the server sees it: the in-memory one (see [`super::nodes`]),
//! except that a Browse of a node in camloop's namespace is answered here. The stack's
//! in-memory manager (async-opcua 0.19, `InMemoryNodeManager::browse`) marks every node it
//! is handed `Good` before looking it up, and lists references in its hash set's order,
//! which changes from one start to the next. Here a node of camloop's namespace that does
//! not exist is `BadNodeIdUnknown`, and references come in a fixed order: machines as
//! configured, features in the recipe's grinding order, a feature's values in the order of
//! the address space's table, everything else by node id.

use std::collections::{HashMap, VecDeque};
use std::sync::Arc;

use async_trait::async_trait;
use opcua::nodes::TypeTree;
use opcua::server::CreateMonitoredItem;
use opcua::server::address_space::AddressSpace;
use opcua::server::diagnostics::NamespaceMetadata;
use opcua::server::node_manager::memory::InMemoryNodeManager;
use opcua::server::node_manager::{
    AddNodeItem, AddReferenceItem, AddReferenceResult, BrowseNode, BrowsePathItem, DeleteNodeItem,
    DeleteReferenceItem, ExternalReference, ExternalReferenceRequest, HistoryNode,
    HistoryUpdateNode, MethodCall, MonitoredItemRef, MonitoredItemUpdateRef, NodeManager,
    QueryRequest, ReadNode, RegisterNodeItem, RequestContext, ServerContext, WriteNode,
};
use opcua::types::{
    BrowseDescriptionResultMask, BrowseDirection, ExpandedNodeId, ExpandedNodeId as Expanded,
    MonitoringMode, NodeClass, NodeId, ReadAnnotationDataDetails, ReadAtTimeDetails,
    ReadEventDetails, ReadProcessedDetails, ReadRawModifiedDetails, ReferenceDescription,
    ReferenceTypeId, StatusCode, TimestampsToReturn,
};

use super::nodes::CamloopNodes;
use super::space::{FeatureValue, Ids, MachineLayout};

/// camloop's nodes, with Browse answered in order (see the module's notes).
pub(crate) struct Ordered {
    pub(crate) inner: Arc<InMemoryNodeManager<CamloopNodes>>,
    ns: u16,
    /// Where a node comes among its siblings (nodes not here come after, by node id).
    rank: HashMap<NodeId, usize>,
}

/// The references of a camloop node still to be sent after a full Browse reply.
struct Remaining {
    references: VecDeque<ReferenceDescription>,
}

impl Ordered {
    pub(crate) fn new(
        inner: Arc<InMemoryNodeManager<CamloopNodes>>,
        layout: &[MachineLayout],
    ) -> Self {
        let ids = inner.inner().ids();
        Self {
            ns: ids.ns,
            rank: ranks(ids, layout),
            inner,
        }
    }

    fn is_ours(&self, node: &NodeId) -> bool {
        node.namespace == self.ns
    }

    /// Answers one Browse of a node in camloop's namespace.
    fn browse_ours(&self, space: &AddressSpace, tree: &dyn TypeTree, node: &mut BrowseNode) {
        if let Some(mut rest) = node.take_continuation_point::<Remaining>() {
            node.set_status(StatusCode::Good);
            while node.remaining() > 0 {
                let Some(r) = rest.references.pop_front() else {
                    break;
                };
                // Filtered when it was found.
                node.add_unchecked(r);
            }
            if !rest.references.is_empty() {
                node.set_next_continuation_point(rest);
            }
            return;
        }
        let source = node.node_id().clone();
        if !space.node_exists(&source) {
            node.set_status(StatusCode::BadNodeIdUnknown);
            return;
        }
        node.set_status(StatusCode::Good);
        let filter = match node.reference_type_id() {
            t if t.is_null() => None,
            t => t
                .as_reference_type_id()
                .ok()
                .map(|t| (t, node.include_subtypes())),
        };
        let mut found = Vec::new();
        for r in space.find_references(&source, filter, tree, node.browse_direction()) {
            match space.find_node(r.target_node) {
                Some(target) => found.push(describe(space, tree, r, target, node.result_mask())),
                None if !self.is_ours(r.target_node) => {
                    node.push_external_reference(ExternalReference::new(
                        r.target_node.clone().into(),
                        r.reference_type.clone(),
                        r.direction,
                    ));
                }
                None => {}
            }
        }
        found.sort_by_cached_key(|d| {
            let rank = self
                .rank
                .get(&d.node_id.node_id)
                .copied()
                .unwrap_or(usize::MAX);
            (
                !d.is_forward,
                rank,
                d.node_id.node_id.to_string(),
                d.reference_type_id.to_string(),
            )
        });
        let mut rest = VecDeque::new();
        for d in found {
            if let AddReferenceResult::Full(d) = node.add(tree, d) {
                rest.push_back(d);
            }
        }
        if !rest.is_empty() {
            node.set_next_continuation_point(Box::new(Remaining { references: rest }));
        }
    }
}

/// A reference to `target` as a Browse reply gives it (as the stack's in-memory manager does).
fn describe(
    space: &AddressSpace,
    tree: &dyn TypeTree,
    r: opcua::nodes::ReferenceRef<'_>,
    target: &opcua::server::address_space::NodeType,
    mask: BrowseDescriptionResultMask,
) -> ReferenceDescription {
    let node = target.as_node();
    let typed = matches!(node.node_class(), NodeClass::Object | NodeClass::Variable);
    let type_definition =
        match mask.contains(BrowseDescriptionResultMask::RESULT_MASK_TYPE_DEFINITION) && typed {
            true => space
                .find_references(
                    node.node_id(),
                    Some((ReferenceTypeId::HasTypeDefinition, false)),
                    tree,
                    BrowseDirection::Forward,
                )
                .next()
                .map_or_else(ExpandedNodeId::null, |t| {
                    Expanded::new(t.target_node.clone())
                }),
            false => ExpandedNodeId::null(),
        };
    ReferenceDescription {
        reference_type_id: r.reference_type.clone(),
        is_forward: matches!(r.direction, opcua::nodes::ReferenceDirection::Forward),
        node_id: Expanded::new(node.node_id().clone()),
        browse_name: node.browse_name().clone(),
        display_name: node.display_name().clone(),
        node_class: node.node_class(),
        type_definition,
    }
}

/// Machines as configured, each machine's features in grinding order, a feature's values
/// in the address space's order.
fn ranks(ids: Ids, layout: &[MachineLayout]) -> HashMap<NodeId, usize> {
    let mut rank = HashMap::new();
    for (i, m) in layout.iter().enumerate() {
        rank.insert(ids.machine(&m.name), i);
        for (j, f) in m.features.iter().enumerate() {
            rank.insert(ids.feature(&m.name, f), j);
            for (k, v) in <FeatureValue as strum::IntoEnumIterator>::iter().enumerate() {
                rank.insert(ids.value(&m.name, f, v), k);
            }
        }
    }
    rank
}

#[async_trait]
impl NodeManager for Ordered {
    fn owns_node(&self, id: &NodeId) -> bool {
        self.inner.owns_node(id)
    }

    fn name(&self) -> &str {
        self.inner.name()
    }

    fn owns_server_events(&self) -> bool {
        self.inner.owns_server_events()
    }

    fn handle_new_node(&self, parent_id: &ExpandedNodeId) -> bool {
        self.inner.handle_new_node(parent_id)
    }

    fn namespaces_for_user(&self, context: &RequestContext) -> Vec<NamespaceMetadata> {
        self.inner.namespaces_for_user(context)
    }

    async fn init(&self, type_tree: &mut opcua::nodes::DefaultTypeTree, context: ServerContext) {
        self.inner.init(type_tree, context).await
    }

    async fn resolve_external_references(
        &self,
        context: &RequestContext,
        items: &mut [&mut ExternalReferenceRequest],
    ) {
        self.inner.resolve_external_references(context, items).await
    }

    async fn browse(
        &self,
        context: &RequestContext,
        nodes: &mut [BrowseNode],
    ) -> Result<(), StatusCode> {
        // Camloop's nodes first: the service keeps each node's place by its input index.
        nodes.sort_by_key(|n| !self.is_ours(n.node_id()));
        let split = nodes.partition_point(|n| self.is_ours(n.node_id()));
        let (ours, others) = nodes.split_at_mut(split);
        {
            let space = self.inner.address_space().read();
            let tree = context.type_tree.read();
            for node in ours.iter_mut() {
                self.browse_ours(&space, &*tree, node);
            }
        }
        if others.is_empty() {
            return Ok(());
        }
        self.inner.browse(context, others).await
    }

    async fn read(
        &self,
        context: &RequestContext,
        max_age: f64,
        timestamps: TimestampsToReturn,
        nodes: &mut [&mut ReadNode],
    ) -> Result<(), StatusCode> {
        self.inner.read(context, max_age, timestamps, nodes).await
    }

    async fn history_read_raw_modified(
        &self,
        context: &RequestContext,
        details: &ReadRawModifiedDetails,
        nodes: &mut [&mut HistoryNode],
        timestamps: TimestampsToReturn,
    ) -> Result<(), StatusCode> {
        let inner = &self.inner;
        inner
            .history_read_raw_modified(context, details, nodes, timestamps)
            .await
    }

    async fn history_read_processed(
        &self,
        context: &RequestContext,
        details: &ReadProcessedDetails,
        nodes: &mut [&mut HistoryNode],
        timestamps: TimestampsToReturn,
    ) -> Result<(), StatusCode> {
        let inner = &self.inner;
        inner
            .history_read_processed(context, details, nodes, timestamps)
            .await
    }

    async fn history_read_at_time(
        &self,
        context: &RequestContext,
        details: &ReadAtTimeDetails,
        nodes: &mut [&mut HistoryNode],
        timestamps: TimestampsToReturn,
    ) -> Result<(), StatusCode> {
        let inner = &self.inner;
        inner
            .history_read_at_time(context, details, nodes, timestamps)
            .await
    }

    async fn history_read_events(
        &self,
        context: &RequestContext,
        details: &ReadEventDetails,
        nodes: &mut [&mut HistoryNode],
        timestamps: TimestampsToReturn,
    ) -> Result<(), StatusCode> {
        let inner = &self.inner;
        inner
            .history_read_events(context, details, nodes, timestamps)
            .await
    }

    async fn history_read_annotations(
        &self,
        context: &RequestContext,
        details: &ReadAnnotationDataDetails,
        nodes: &mut [&mut HistoryNode],
        timestamps: TimestampsToReturn,
    ) -> Result<(), StatusCode> {
        let inner = &self.inner;
        inner
            .history_read_annotations(context, details, nodes, timestamps)
            .await
    }

    async fn write(
        &self,
        context: &RequestContext,
        nodes: &mut [&mut WriteNode],
    ) -> Result<(), StatusCode> {
        self.inner.write(context, nodes).await
    }

    async fn history_update(
        &self,
        context: &RequestContext,
        nodes: &mut [&mut HistoryUpdateNode],
    ) -> Result<(), StatusCode> {
        self.inner.history_update(context, nodes).await
    }

    async fn translate_browse_paths_to_node_ids(
        &self,
        context: &RequestContext,
        nodes: &mut [&mut BrowsePathItem],
    ) -> Result<(), StatusCode> {
        self.inner
            .translate_browse_paths_to_node_ids(context, nodes)
            .await
    }

    async fn register_nodes(
        &self,
        context: &RequestContext,
        nodes: &mut [&mut RegisterNodeItem],
    ) -> Result<(), StatusCode> {
        self.inner.register_nodes(context, nodes).await
    }

    async fn unregister_nodes(
        &self,
        context: &RequestContext,
        nodes: &[&NodeId],
    ) -> Result<(), StatusCode> {
        self.inner.unregister_nodes(context, nodes).await
    }

    async fn create_monitored_items(
        &self,
        context: &RequestContext,
        items: &mut [&mut CreateMonitoredItem],
    ) -> Result<(), StatusCode> {
        self.inner.create_monitored_items(context, items).await
    }

    async fn modify_monitored_items(
        &self,
        context: &RequestContext,
        items: &[&MonitoredItemUpdateRef],
    ) {
        self.inner.modify_monitored_items(context, items).await
    }

    async fn set_monitoring_mode(
        &self,
        context: &RequestContext,
        mode: MonitoringMode,
        items: &[&MonitoredItemRef],
    ) {
        self.inner.set_monitoring_mode(context, mode, items).await
    }

    async fn delete_monitored_items(&self, context: &RequestContext, items: &[&MonitoredItemRef]) {
        self.inner.delete_monitored_items(context, items).await
    }

    async fn query(
        &self,
        context: &RequestContext,
        request: &mut QueryRequest,
    ) -> Result<(), StatusCode> {
        self.inner.query(context, request).await
    }

    async fn call(
        &self,
        context: &RequestContext,
        methods: &mut [&mut MethodCall],
    ) -> Result<(), StatusCode> {
        self.inner.call(context, methods).await
    }

    async fn add_nodes(
        &self,
        context: &RequestContext,
        nodes: &mut [&mut AddNodeItem],
    ) -> Result<(), StatusCode> {
        self.inner.add_nodes(context, nodes).await
    }

    async fn add_references(
        &self,
        context: &RequestContext,
        references: &mut [&mut AddReferenceItem],
    ) -> Result<(), StatusCode> {
        self.inner.add_references(context, references).await
    }

    async fn delete_nodes(
        &self,
        context: &RequestContext,
        nodes: &mut [&mut DeleteNodeItem],
    ) -> Result<(), StatusCode> {
        self.inner.delete_nodes(context, nodes).await
    }

    async fn delete_node_references(
        &self,
        context: &RequestContext,
        to_delete: &[&DeleteNodeItem],
    ) {
        self.inner.delete_node_references(context, to_delete).await
    }

    async fn delete_references(
        &self,
        context: &RequestContext,
        references: &mut [&mut DeleteReferenceItem],
    ) -> Result<(), StatusCode> {
        self.inner.delete_references(context, references).await
    }
}
