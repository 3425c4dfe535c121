//! camloop's node manager: an in-memory address space (values are pushed by the feed, see
//! [`super::feed`]) whose method calls run async with the caller's identity.

use async_trait::async_trait;
use opcua::server::CreateMonitoredItem;
use opcua::server::address_space::AddressSpace;
use opcua::server::diagnostics::NamespaceMetadata;
use opcua::server::node_manager::memory::{
    InMemoryNodeManagerImpl, InMemoryNodeManagerImplBuilder,
};
use opcua::server::node_manager::{MethodCall, MonitoredItemRef, RequestContext, ServerContext};
use opcua::sync::RwLock;
use opcua::types::{AttributeId, StatusCode};
use std::sync::Arc;

use super::events::Listeners;
use super::methods::ArgumentError;
use super::space::{self, Ids, MachineLayout, Method};
use crate::port::Service;

/// What the node manager is built from.
pub(crate) struct Builder {
    pub(crate) layout: Vec<MachineLayout>,
    pub(crate) service: Arc<dyn Service>,
    pub(crate) listeners: Arc<Listeners>,
}

pub(crate) struct CamloopNodes {
    namespace: NamespaceMetadata,
    ids: Ids,
    layout: Vec<MachineLayout>,
    service: Arc<dyn Service>,
    listeners: Arc<Listeners>,
}

impl CamloopNodes {
    /// camloop's node ids (its namespace index).
    pub(crate) fn ids(&self) -> Ids {
        self.ids
    }
}

impl InMemoryNodeManagerImplBuilder for Builder {
    type Impl = CamloopNodes;

    fn build(self, context: ServerContext, address_space: &mut AddressSpace) -> CamloopNodes {
        let ns = context
            .type_tree
            .write()
            .namespaces_mut()
            .add_namespace(space::NAMESPACE_URI);
        address_space.add_namespace(space::NAMESPACE_URI, ns);
        CamloopNodes {
            namespace: NamespaceMetadata {
                namespace_uri: space::NAMESPACE_URI.to_string(),
                namespace_index: ns,
                ..Default::default()
            },
            ids: Ids { ns },
            layout: self.layout,
            service: self.service,
            listeners: self.listeners,
        }
    }
}

#[async_trait]
impl InMemoryNodeManagerImpl for CamloopNodes {
    async fn init(&self, address_space: &mut AddressSpace, _context: ServerContext) {
        // The stack loads the event types into its type tree after this (it holds the tree's
        // lock meanwhile, so it must not be taken here).
        space::build(address_space, self.ids, &self.layout);
    }

    fn name(&self) -> &str {
        "camloop"
    }

    fn namespaces(&self) -> Vec<NamespaceMetadata> {
        vec![self.namespace.clone()]
    }

    /// Event monitored items on camloop's notifiers are delivered by the feed (see
    /// [`super::events`]): recorded here.
    async fn create_event_monitored_items(
        &self,
        context: &RequestContext,
        _address_space: &RwLock<AddressSpace>,
        items: &mut [&mut &mut CreateMonitoredItem],
    ) {
        for item in items.iter() {
            if item.status_code().is_good() {
                let node = item.item_to_monitor().node_id.clone();
                self.listeners.add(context.session_id, node, item.handle());
            }
        }
    }

    async fn delete_monitored_items(&self, _context: &RequestContext, items: &[&MonitoredItemRef]) {
        let events: Vec<&MonitoredItemRef> = items
            .iter()
            .copied()
            .filter(|i| i.attribute() == AttributeId::EventNotifier)
            .collect();
        self.listeners.remove(&events);
    }

    async fn call(
        &self,
        context: &RequestContext,
        _address_space: &RwLock<AddressSpace>,
        methods_to_call: &mut [&mut &mut MethodCall],
    ) -> Result<(), StatusCode> {
        let token = context.user_token();
        let user = (!token.is_anonymous()).then(|| token.0.clone());
        let client = {
            let session = context.session().read();
            format!(
                "{} ({})",
                session.application_description().application_uri,
                session.session_name()
            )
        };
        for call in methods_to_call.iter_mut() {
            let Some((machine, method)) = Method::parse(self.ids, call.method_id()) else {
                call.set_status(StatusCode::BadMethodInvalid);
                continue;
            };
            let args = call.arguments().to_vec();
            match super::methods::check_arguments(method, &args) {
                Ok(()) => {}
                Err(ArgumentError::Missing) => {
                    call.set_status(StatusCode::BadArgumentsMissing);
                    continue;
                }
                Err(ArgumentError::TooMany) => {
                    call.set_status(StatusCode::BadTooManyArguments);
                    continue;
                }
                Err(ArgumentError::Types(results)) => {
                    // BadInvalidArgument, with BadTypeMismatch on each argument of the wrong
                    // type (OPC 10000-4 §5.11.2).
                    call.set_argument_error(results);
                    continue;
                }
            }
            let done = super::methods::call(
                self.service.as_ref(),
                user.as_deref(),
                &client,
                &machine,
                method,
                &args,
            )
            .await;
            match done {
                Ok(outputs) => {
                    call.set_outputs(outputs);
                    call.set_status(StatusCode::Good);
                }
                Err(status) => call.set_status(status),
            }
        }
        Ok(())
    }
}
