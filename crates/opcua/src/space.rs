//! The address space camloop serves: `Objects/Machines/<machine>` with its identification,
//! one object per feature (lobe or pin) holding the latest result and the loop's state, a
//! `Results` folder after the OPC 40001-101 pattern, the two write methods, and the event
//! types camloop raises. Node ids are strings in camloop's namespace, built here only.

use camloop_core::names::{FeatureName, MachineName};
use opcua::server::address_space::{
    AccessLevel, AddressSpace, EventNotifier, MethodBuilder, ObjectBuilder, ObjectTypeBuilder,
    VariableBuilder,
};
use opcua::types::{
    Argument, DataTypeId, DataValue, EUInformation, LocalizedText, NodeId, ObjectId, ObjectTypeId,
    QualifiedName, ReferenceTypeId, StatusCode, UAString, VariableTypeId, Variant,
};

/// camloop's namespace.
pub(crate) const NAMESPACE_URI: &str = "urn:camloop:ua";

/// UNECE Rec. 20 codes as OPC UA `EUInformation.unitId` (the code's characters packed).
const UNIT_MICROMETRE: (&str, i32, &str) = ("µm", 0x3448, "micrometre"); // "4H"
const UNIT_DEGREE: (&str, i32, &str) = ("°", 0x4444, "degree"); // "DD"
const UNECE_URI: &str = "http://www.opcfoundation.org/UA/units/un/cefact";

/// One machine as the address space shows it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MachineLayout {
    pub name: MachineName,
    /// The recipe (part) name.
    pub recipe: String,
    /// Its features in grinding order.
    pub features: Vec<FeatureName>,
}

/// Which value of a feature's result object a variable holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, strum::IntoStaticStr, strum::EnumIter)]
pub(crate) enum FeatureValue {
    PartId,
    Time,
    Verdict,
    MaxErrorUm,
    ProfileErrorUm,
    SizeErrorUm,
    PhaseErrorDeg,
    RepeatabilityUm,
    /// The whole result as one JSON string (written with the scalars, in the same write).
    LatestResult,
    TableVersionInForce,
    WaitingVersion,
    LearningFrozen,
    FrozenReason,
    BlockedByGuard,
    GuardReason,
}

impl FeatureValue {
    /// Browse name (units ride in `EngineeringUnits`, not in the name).
    pub(crate) fn browse_name(self) -> &'static str {
        match self {
            FeatureValue::MaxErrorUm => "MaxError",
            FeatureValue::ProfileErrorUm => "ProfileError",
            FeatureValue::SizeErrorUm => "SizeError",
            FeatureValue::PhaseErrorDeg => "PhaseError",
            FeatureValue::RepeatabilityUm => "Repeatability",
            other => other.into(),
        }
    }

    fn data_type(self) -> DataTypeId {
        use FeatureValue::*;
        match self {
            PartId | Verdict | FrozenReason | GuardReason | LatestResult => DataTypeId::String,
            Time => DataTypeId::DateTime,
            MaxErrorUm | ProfileErrorUm | SizeErrorUm | PhaseErrorDeg | RepeatabilityUm => {
                DataTypeId::Double
            }
            TableVersionInForce | WaitingVersion => DataTypeId::Int64,
            LearningFrozen | BlockedByGuard => DataTypeId::Boolean,
        }
    }

    /// Whether the value is a part's result (written from its part's event only).
    pub(crate) fn is_result(self) -> bool {
        use FeatureValue::*;
        matches!(
            self,
            PartId
                | Time
                | Verdict
                | MaxErrorUm
                | ProfileErrorUm
                | SizeErrorUm
                | PhaseErrorDeg
                | RepeatabilityUm
                | LatestResult
        )
    }

    fn unit(self) -> Option<(&'static str, i32, &'static str)> {
        use FeatureValue::*;
        match self {
            MaxErrorUm | ProfileErrorUm | SizeErrorUm | RepeatabilityUm => Some(UNIT_MICROMETRE),
            PhaseErrorDeg => Some(UNIT_DEGREE),
            _ => None,
        }
    }
}

/// Node ids of camloop's namespace `ns`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Ids {
    pub(crate) ns: u16,
}

impl Ids {
    fn id(self, path: &str) -> NodeId {
        NodeId::new(self.ns, path.to_string())
    }
    fn name(self, name: &str) -> QualifiedName {
        QualifiedName::new(self.ns, name)
    }
    pub(crate) fn machines(self) -> NodeId {
        self.id("Machines")
    }
    pub(crate) fn machine(self, m: &str) -> NodeId {
        self.id(&format!("Machines/{m}"))
    }
    pub(crate) fn feature(self, m: &str, f: &str) -> NodeId {
        self.id(&format!("Machines/{m}/Features/{f}"))
    }
    pub(crate) fn value(self, m: &str, f: &str, v: FeatureValue) -> NodeId {
        self.id(&format!("Machines/{m}/Features/{f}/{}", v.browse_name()))
    }
    pub(crate) fn grinding_order(self, m: &str) -> NodeId {
        self.id(&format!("Machines/{m}/GrindingOrder"))
    }
    pub(crate) fn dressing_count(self, m: &str) -> NodeId {
        self.id(&format!("Machines/{m}/DressingCount"))
    }
    pub(crate) fn journal_failing(self, m: &str) -> NodeId {
        self.id(&format!("Machines/{m}/JournalFailing"))
    }
    pub(crate) fn method(self, m: &str, method: Method) -> NodeId {
        match method {
            Method::GetLatestResult | Method::GetResultById => {
                self.id(&format!("Machines/{m}/Results/{}", method.name()))
            }
            _ => self.id(&format!("Machines/{m}/{}", method.name())),
        }
    }
    pub(crate) fn alarm_type(self) -> NodeId {
        self.id("CamloopAlarmEventType")
    }
    pub(crate) fn result_ready_type(self) -> NodeId {
        self.id("ResultReadyEventType")
    }
}

/// A method argument: name and type.
type Arg = (&'static str, DataTypeId);

/// The methods of a machine.
#[derive(Debug, Clone, Copy, PartialEq, Eq, strum::EnumIter)]
pub(crate) enum Method {
    Rollback,
    AcknowledgeEvent,
    GetLatestResult,
    GetResultById,
}

impl Method {
    pub(crate) fn name(self) -> &'static str {
        match self {
            Method::Rollback => "Rollback",
            Method::AcknowledgeEvent => "AcknowledgeEvent",
            Method::GetLatestResult => "GetLatestResult",
            Method::GetResultById => "GetResultById",
        }
    }

    /// In and out arguments: name and type.
    pub(crate) fn arguments(self) -> (Vec<Arg>, Vec<Arg>) {
        use DataTypeId::{BaseDataType, DateTime, Int64, String};
        let result_out = vec![
            ("ResultId", Int64),
            ("PartId", String),
            ("Time", DateTime),
            ("Verdict", String),
            ("ResultJson", String),
        ];
        match self {
            Method::Rollback => (
                vec![("Feature", String), ("Version", Int64)],
                vec![("NewVersion", Int64), ("Message", String)],
            ),
            // camloop's id (Int64, from the events API) or the event's OPC UA EventId
            // (ByteString): either type is taken.
            Method::AcknowledgeEvent => {
                (vec![("EventId", BaseDataType)], vec![("Message", String)])
            }
            Method::GetLatestResult => (vec![("Feature", String)], result_out),
            Method::GetResultById => (vec![("ResultId", Int64)], result_out),
        }
    }

    /// The method a node id names, with its machine.
    pub(crate) fn parse(ids: Ids, node: &NodeId) -> Option<(String, Method)> {
        if node.namespace != ids.ns {
            return None;
        }
        let opcua::types::Identifier::String(s) = &node.identifier else {
            return None;
        };
        let rest = s.as_ref().strip_prefix("Machines/")?;
        let (machine, tail) = rest.split_once('/')?;
        let method = <Method as strum::IntoEnumIterator>::iter()
            .find(|m| tail == m.name() || tail == format!("Results/{}", m.name()))?;
        Some((machine.to_string(), method))
    }
}

/// Adds camloop's types and every machine's nodes.
pub(crate) fn build(space: &mut AddressSpace, ids: Ids, machines: &[MachineLayout]) {
    event_types(space, ids);
    ObjectBuilder::new(&ids.machines(), ids.name("Machines"), "Machines")
        .is_folder()
        .has_type_definition(ObjectTypeId::FolderType)
        .organized_by(ObjectId::ObjectsFolder)
        .event_notifier(EventNotifier::SUBSCRIBE_TO_EVENTS)
        .insert(space);
    // The notifier hierarchy (OPC 10000-3 §7.16): Server → Machines → each machine, whose
    // features are its event sources.
    space.insert_reference(
        &ObjectId::Server.into(),
        &ids.machines(),
        ReferenceTypeId::HasNotifier,
    );
    for m in machines {
        machine(space, ids, m);
        space.insert_reference(
            &ids.machines(),
            &ids.machine(&m.name),
            ReferenceTypeId::HasNotifier,
        );
        for f in &m.features {
            space.insert_reference(
                &ids.machine(&m.name),
                &ids.feature(&m.name, f),
                ReferenceTypeId::HasEventSource,
            );
        }
    }
}

fn event_types(space: &mut AddressSpace, ids: Ids) {
    ObjectTypeBuilder::new(
        &ids.alarm_type(),
        ids.name("CamloopAlarmEventType"),
        "CamloopAlarmEventType",
    )
    .subtype_of(ObjectTypeId::BaseEventType)
    .insert(space);
    ObjectTypeBuilder::new(
        &ids.result_ready_type(),
        ids.name("ResultReadyEventType"),
        "ResultReadyEventType",
    )
    .subtype_of(ObjectTypeId::BaseEventType)
    .insert(space);
}

fn machine(space: &mut AddressSpace, ids: Ids, m: &MachineLayout) {
    let node = ids.machine(&m.name);
    ObjectBuilder::new(&node, ids.name(&m.name), m.name.as_str())
        .has_type_definition(ObjectTypeId::BaseObjectType)
        .organized_by(ids.machines())
        .event_notifier(EventNotifier::SUBSCRIBE_TO_EVENTS)
        .insert(space);
    let ident = ids.id(&format!("Machines/{}/Identification", m.name));
    ObjectBuilder::new(&ident, ids.name("Identification"), "Identification")
        .has_type_definition(ObjectTypeId::FolderType)
        .component_of(node.clone())
        .insert(space);
    let fixed = [
        ("Name", m.name.to_string()),
        ("Recipe", m.recipe.clone()),
        ("SoftwareVersion", env!("CARGO_PKG_VERSION").to_string()),
        ("Manufacturer", "camloop".to_string()),
    ];
    for (name, value) in fixed {
        let id = ids.id(&format!("Machines/{}/Identification/{name}", m.name));
        read_only(&id, ids.name(name), name, DataTypeId::String)
            .value(UAString::from(value))
            .property_of(ident.clone())
            .has_type_definition(VariableTypeId::PropertyType)
            .insert(space);
    }
    read_only(
        &ids.dressing_count(&m.name),
        ids.name("DressingCount"),
        "DressingCount",
        DataTypeId::Int64,
    )
    .value(0i64)
    .component_of(node.clone())
    .has_type_definition(VariableTypeId::BaseDataVariableType)
    .insert(space);
    read_only(
        &ids.journal_failing(&m.name),
        ids.name("JournalFailing"),
        "JournalFailing",
        DataTypeId::Boolean,
    )
    .value(false)
    .component_of(node.clone())
    .has_type_definition(VariableTypeId::BaseDataVariableType)
    .insert(space);
    let features = ids.id(&format!("Machines/{}/Features", m.name));
    ObjectBuilder::new(&features, ids.name("Features"), "Features")
        .is_folder()
        .has_type_definition(ObjectTypeId::FolderType)
        .component_of(node.clone())
        .insert(space);
    for f in &m.features {
        feature(space, ids, &m.name, f, &features);
    }
    // The library answers a Browse in its hash set's order, which changes from start to
    // start: the recipe's order is given here (on the machine: the Features folder holds
    // the features only).
    let order: Vec<UAString> = m
        .features
        .iter()
        .map(|f| UAString::from(f.as_str()))
        .collect();
    read_only(
        &ids.grinding_order(&m.name),
        ids.name("GrindingOrder"),
        "GrindingOrder",
        DataTypeId::String,
    )
    .value_rank(1)
    .value(Variant::from(order))
    .property_of(node.clone())
    .has_type_definition(VariableTypeId::PropertyType)
    .insert(space);
    let results = ids.id(&format!("Machines/{}/Results", m.name));
    ObjectBuilder::new(&results, ids.name("Results"), "Results")
        .is_folder()
        .has_type_definition(ObjectTypeId::FolderType)
        .component_of(node.clone())
        .insert(space);
    for method in <Method as strum::IntoEnumIterator>::iter() {
        let parent = match method {
            Method::GetLatestResult | Method::GetResultById => results.clone(),
            _ => node.clone(),
        };
        add_method(space, ids, &m.name, method, parent);
    }
}

fn feature(space: &mut AddressSpace, ids: Ids, m: &str, f: &str, parent: &NodeId) {
    let node = ids.feature(m, f);
    ObjectBuilder::new(&node, ids.name(f), f)
        .has_type_definition(ObjectTypeId::BaseObjectType)
        .component_of(parent.clone())
        .insert(space);
    for v in <FeatureValue as strum::IntoEnumIterator>::iter() {
        let id = ids.value(m, f, v);
        let name = v.browse_name();
        let b = read_only(&id, ids.name(name), name, v.data_type()).component_of(node.clone());
        match v.unit() {
            Some(unit) => {
                b.has_type_definition(VariableTypeId::BaseAnalogType)
                    .insert(space);
                engineering_units(space, ids, &id, unit);
            }
            None => {
                b.has_type_definition(VariableTypeId::BaseDataVariableType)
                    .insert(space);
            }
        }
        if v.is_result() {
            waiting_for_initial_data(space, &id);
        }
    }
}

/// A result variable before its feature's first part since the start: no value, and a
/// status that says so (not `Null` with `Good`).
fn waiting_for_initial_data(space: &mut AddressSpace, id: &NodeId) {
    if let Some(opcua::server::address_space::NodeType::Variable(v)) = space.find_mut(id) {
        v.set_data_value(DataValue {
            // The stack returns a value's status only with a value: an empty one.
            value: Some(Variant::Empty),
            status: Some(StatusCode::BadWaitingForInitialData),
            source_timestamp: None,
            server_timestamp: Some(opcua::types::DateTime::now()),
            ..DataValue::default()
        });
    }
}

/// A read-only variable with no value yet.
fn read_only(id: &NodeId, name: QualifiedName, display: &str, ty: DataTypeId) -> VariableBuilder {
    VariableBuilder::new(id, name, display)
        .data_type(ty)
        .access_level(AccessLevel::CURRENT_READ)
        .user_access_level(AccessLevel::CURRENT_READ)
}

fn engineering_units(
    space: &mut AddressSpace,
    ids: Ids,
    of: &NodeId,
    (symbol, unit_id, description): (&str, i32, &str),
) {
    let opcua::types::Identifier::String(s) = &of.identifier else {
        return;
    };
    let id = ids.id(&format!("{}/EngineeringUnits", s.as_ref()));
    let eu = EUInformation {
        namespace_uri: UNECE_URI.into(),
        unit_id,
        display_name: LocalizedText::new("", symbol),
        description: LocalizedText::new("", description),
    };
    VariableBuilder::new(&id, "EngineeringUnits", "EngineeringUnits")
        .data_type(DataTypeId::EUInformation)
        .value(Variant::from(opcua::types::ExtensionObject::from_message(
            eu,
        )))
        .access_level(AccessLevel::CURRENT_READ)
        .user_access_level(AccessLevel::CURRENT_READ)
        .property_of(of.clone())
        .has_type_definition(VariableTypeId::PropertyType)
        .insert(space);
}

fn add_method(space: &mut AddressSpace, ids: Ids, m: &str, method: Method, parent: NodeId) {
    let id = ids.method(m, method);
    let (inputs, outputs) = method.arguments();
    let args = |list: Vec<Arg>| -> Vec<Argument> { list.into_iter().map(|a| a.into()).collect() };
    let opcua::types::Identifier::String(s) = &id.identifier else {
        return;
    };
    let path = s.as_ref().to_string();
    let mut b = MethodBuilder::new(&id, ids.name(method.name()), method.name())
        .component_of(parent)
        .executable(true)
        .user_executable(true);
    b = b.input_args(
        space,
        &ids.id(&format!("{path}/InputArguments")),
        &args(inputs),
    );
    b = b.output_args(
        space,
        &ids.id(&format!("{path}/OutputArguments")),
        &args(outputs),
    );
    b.insert(space);
}

/// Nodes per machine with `features` features (for the docs and the closing note).
pub(crate) fn nodes_per_machine(features: usize) -> usize {
    let values = <FeatureValue as strum::IntoEnumIterator>::iter().count();
    let analog = <FeatureValue as strum::IntoEnumIterator>::iter()
        .filter(|v| v.unit().is_some())
        .count();
    // machine, Identification + 4, DressingCount, JournalFailing, GrindingOrder, Features,
    // Results, 4 methods with 2 argument variables each.
    let fixed = 1 + 5 + 2 + 3 + 4 * 3;
    fixed + features * (1 + values + analog)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn demo() -> (AddressSpace, Ids) {
        let mut space = AddressSpace::new();
        space.add_namespace(NAMESPACE_URI, 2);
        let ids = Ids { ns: 2 };
        let layout = MachineLayout {
            name: "G7".parse().unwrap(),
            recipe: "demo".into(),
            features: vec!["IN1".parse().unwrap(), "EX1".parse().unwrap()],
        };
        build(&mut space, ids, &[layout]);
        (space, ids)
    }

    #[test]
    fn method_node_ids_name_their_machine_and_method_and_nothing_else_does() {
        let ids = Ids { ns: 2 };
        for method in <Method as strum::IntoEnumIterator>::iter() {
            let id = ids.method("G7", method);
            assert_eq!(Method::parse(ids, &id), Some(("G7".to_string(), method)));
            let foreign = NodeId::new(
                3,
                match &id.identifier {
                    opcua::types::Identifier::String(s) => s.as_ref().to_string(),
                    _ => unreachable!(),
                },
            );
            assert_eq!(Method::parse(ids, &foreign), None, "another namespace");
        }
        let value = ids.value("G7", "IN1", FeatureValue::PartId);
        assert_eq!(Method::parse(ids, &value), None);
    }

    #[test]
    fn the_space_has_every_machine_feature_value_unit_and_method() {
        let (space, ids) = demo();
        assert!(space.node_exists(&ids.machines()));
        assert!(space.node_exists(&ids.machine("G7")));
        for f in ["IN1", "EX1"] {
            for v in <FeatureValue as strum::IntoEnumIterator>::iter() {
                assert!(space.node_exists(&ids.value("G7", f, v)), "{f} {v:?}");
            }
        }
        for method in <Method as strum::IntoEnumIterator>::iter() {
            assert!(space.node_exists(&ids.method("G7", method)), "{method:?}");
        }
        // The recipe's order, whatever order a Browse gives.
        let Some(opcua::server::address_space::NodeType::Variable(order)) =
            space.find(&ids.grinding_order("G7"))
        else {
            panic!("no GrindingOrder")
        };
        let order = order.value(
            opcua::types::TimestampsToReturn::Neither,
            &opcua::types::NumericRange::None,
            &opcua::types::DataEncoding::Binary,
            0.0,
        );
        let Some(Variant::Array(a)) = order.value else {
            panic!("{order:?}")
        };
        let names: Vec<String> = a.values.iter().map(|v| v.to_string()).collect();
        assert_eq!(names, ["IN1", "EX1"]);
        // UNECE Rec. 20 packs the code's characters: "4H" is the micrometre.
        let micrometre = (i32::from(b'4') << 8) | i32::from(b'H');
        let eu = NodeId::new(2, "Machines/G7/Features/IN1/ProfileError/EngineeringUnits");
        let Some(opcua::server::address_space::NodeType::Variable(v)) = space.find(&eu) else {
            panic!("no EngineeringUnits")
        };
        let value = v.value(
            opcua::types::TimestampsToReturn::Neither,
            &opcua::types::NumericRange::None,
            &opcua::types::DataEncoding::Binary,
            0.0,
        );
        let Some(Variant::ExtensionObject(o)) = value.value else {
            panic!("not an extension object: {value:?}")
        };
        let info = o.inner_as::<EUInformation>().expect("EUInformation");
        assert_eq!(info.unit_id, micrometre);
        assert_eq!(info.display_name.text.as_ref(), "µm");
    }
}
