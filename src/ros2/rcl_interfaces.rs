//! The `rcl_interfaces` types every ROS 2 node speaks besides its own topics — its log on
//! `/rosout`, its parameters' events on `/parameter_events`, and its six parameter services
//! — as serde structs laid out field for field as their `.msg` and `.srv` files (ROS 2
//! Kilted's `rcl_interfaces`), so that `hiroz-cdr` writes and reads their CDR.
//!
//! Their RIHS01 hashes are the ones a real rclpy node over rmw_zenoh_cpp 0.6.7 declared in
//! its liveliness tokens (`../shared/fixtures/ros2-real/real-rclpy-talker.json`); the tests
//! compare every token ratelab declares with that node's, and `rosbags` (an independent
//! implementation) computes the two message types' hashes again.

use super::rmw_zenoh::entity::{TypeHash, TypeInfo};
use serde::{Deserialize, Serialize};

pub use ratelab_core::ros_types::Time;

/// `rcl_interfaces/msg/Log`'s RIHS01 hash.
pub const LOG_HASH: &str =
    "RIHS01_e28ce254ca8abc06abf92773b74602cdbf116ed34fbaf294fb9f81da9f318eac";

/// `rcl_interfaces/msg/ParameterEvent`'s RIHS01 hash.
pub const PARAMETER_EVENT_HASH: &str =
    "RIHS01_043e627780fcad87a22d225bc2a037361dba713fca6a6b9f4b869a5aa0393204";

/// `rcl_interfaces/msg/Log`'s level of a line logged as information (`Log.INFO`).
pub const LOG_INFO: u8 = 20;
/// `Log.WARN`.
pub const LOG_WARN: u8 = 30;
/// `Log.ERROR`.
pub const LOG_ERROR: u8 = 40;

/// `rcl_interfaces/msg/Log`: one line of a node's log, as `/rosout` carries it.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Log {
    /// When it was logged (rcl stamps `/rosout` with the system clock).
    pub stamp: Time,
    /// [`LOG_INFO`], [`LOG_WARN`], [`LOG_ERROR`] (10 debug, 50 fatal).
    pub level: u8,
    /// The logger's name: the node's (`policy`).
    pub name: String,
    /// The text.
    pub msg: String,
    /// The source file that logged it (empty: not known).
    pub file: String,
    /// The function that logged it (empty: not known).
    pub function: String,
    /// The source line (0: not known).
    pub line: u32,
}

/// A parameter's type, `rcl_interfaces/msg/ParameterType`'s constants.
pub mod parameter_type {
    /// No value: a parameter not set.
    pub const NOT_SET: u8 = 0;
    /// `bool`.
    pub const BOOL: u8 = 1;
    /// `int64`.
    pub const INTEGER: u8 = 2;
    /// `float64`.
    pub const DOUBLE: u8 = 3;
    /// `string`.
    pub const STRING: u8 = 4;
    /// `byte[]`.
    pub const BYTE_ARRAY: u8 = 5;
    /// `bool[]`.
    pub const BOOL_ARRAY: u8 = 6;
    /// `int64[]`.
    pub const INTEGER_ARRAY: u8 = 7;
    /// `float64[]`.
    pub const DOUBLE_ARRAY: u8 = 8;
    /// `string[]`.
    pub const STRING_ARRAY: u8 = 9;
}

/// `rcl_interfaces/msg/ParameterValue`: a value of one of [`parameter_type`]'s types, in
/// the field its `type` names (the others empty).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ParameterValue {
    /// Which field holds the value ([`parameter_type`]).
    #[serde(rename = "type")]
    pub type_: u8,
    /// A `BOOL`.
    pub bool_value: bool,
    /// An `INTEGER`.
    pub integer_value: i64,
    /// A `DOUBLE`.
    pub double_value: f64,
    /// A `STRING`.
    pub string_value: String,
    /// A `BYTE_ARRAY`.
    pub byte_array_value: Vec<u8>,
    /// A `BOOL_ARRAY`.
    pub bool_array_value: Vec<bool>,
    /// An `INTEGER_ARRAY`.
    pub integer_array_value: Vec<i64>,
    /// A `DOUBLE_ARRAY`.
    pub double_array_value: Vec<f64>,
    /// A `STRING_ARRAY`.
    pub string_array_value: Vec<String>,
}

/// `rcl_interfaces/msg/Parameter`: a name and its value.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Parameter {
    /// The name (`rate_hz`; nested names joined by `.`).
    pub name: String,
    /// The value.
    pub value: ParameterValue,
}

/// `rcl_interfaces/msg/ParameterEvent`: a node's parameters declared, changed or deleted.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ParameterEvent {
    /// When (the node's clock).
    pub stamp: Time,
    /// The node's fully qualified name (`/policy`).
    pub node: String,
    /// Declared.
    pub new_parameters: Vec<Parameter>,
    /// Changed.
    pub changed_parameters: Vec<Parameter>,
    /// Undeclared.
    pub deleted_parameters: Vec<Parameter>,
}

/// `rcl_interfaces/msg/FloatingPointRange`: a `DOUBLE` parameter's range.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct FloatingPointRange {
    /// The least value.
    pub from_value: f64,
    /// The greatest value.
    pub to_value: f64,
    /// The step between values (0: any value).
    pub step: f64,
}

/// `rcl_interfaces/msg/IntegerRange`: an `INTEGER` parameter's range.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct IntegerRange {
    /// The least value.
    pub from_value: i64,
    /// The greatest value.
    pub to_value: i64,
    /// The step between values (0: any value).
    pub step: u64,
}

/// `rcl_interfaces/msg/ParameterDescriptor`: what a parameter is.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ParameterDescriptor {
    /// Its name.
    pub name: String,
    /// Its type ([`parameter_type`]).
    #[serde(rename = "type")]
    pub type_: u8,
    /// What it means.
    pub description: String,
    /// Constraints in words.
    pub additional_constraints: String,
    /// It cannot be set.
    pub read_only: bool,
    /// Its type may change when it is set.
    pub dynamic_typing: bool,
    /// A `DOUBLE`'s range (at most one).
    pub floating_point_range: Vec<FloatingPointRange>,
    /// An `INTEGER`'s range (at most one).
    pub integer_range: Vec<IntegerRange>,
}

/// `rcl_interfaces/msg/SetParametersResult`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SetParametersResult {
    /// It was set.
    pub successful: bool,
    /// Why not, when not.
    pub reason: String,
}

/// `rcl_interfaces/msg/ListParametersResult`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ListParametersResult {
    /// The names listed.
    pub names: Vec<String>,
    /// The prefixes (a name's part before its last `.`) among them, each once.
    pub prefixes: Vec<String>,
}

/// `rcl_interfaces/srv/ListParameters` request: names under `prefixes` (none: all), at
/// most `depth` levels below them (0: `DEPTH_RECURSIVE`, every level).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ListParametersRequest {
    /// The prefixes.
    pub prefixes: Vec<String>,
    /// The depth.
    pub depth: u64,
}

/// `rcl_interfaces/srv/ListParameters` response.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ListParametersResponse {
    /// What was found.
    pub result: ListParametersResult,
}

/// The request of `GetParameters`, `GetParameterTypes` and `DescribeParameters`: names.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct NamesRequest {
    /// The parameters' names.
    pub names: Vec<String>,
}

/// `rcl_interfaces/srv/GetParameters` response: the values in the request's order.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct GetParametersResponse {
    /// The values.
    pub values: Vec<ParameterValue>,
}

/// `rcl_interfaces/srv/GetParameterTypes` response: the types in the request's order.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct GetParameterTypesResponse {
    /// The types ([`parameter_type`]).
    pub types: Vec<u8>,
}

/// `rcl_interfaces/srv/DescribeParameters` response.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct DescribeParametersResponse {
    /// The descriptors, in the request's order.
    pub descriptors: Vec<ParameterDescriptor>,
}

/// The request of `SetParameters` and `SetParametersAtomically`: parameters to set.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SetRequest {
    /// The names and new values.
    pub parameters: Vec<Parameter>,
}

/// `rcl_interfaces/srv/SetParameters` response: one result per parameter.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SetParametersResponse {
    /// The results.
    pub results: Vec<SetParametersResult>,
}

/// `rcl_interfaces/srv/SetParametersAtomically` response: one result for all.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SetParametersAtomicallyResponse {
    /// The result.
    pub result: SetParametersResult,
}

/// A service type every ROS 2 node offers: its name under the node's, its type and hash.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ServiceType {
    /// The service's name under its node's (`get_parameters`).
    pub suffix: &'static str,
    /// Its type (`rcl_interfaces/srv/GetParameters`).
    pub type_name: &'static str,
    /// Its type's RIHS01 hash.
    pub hash: &'static str,
}

/// `~/get_type_description` (`type_description_interfaces/srv/GetTypeDescription`, REP
/// 2011): a node's description of a type it uses ([`super::type_description`]).
pub const GET_TYPE_DESCRIPTION: ServiceType = ServiceType {
    suffix: "get_type_description",
    type_name: "type_description_interfaces/srv/GetTypeDescription",
    hash: "RIHS01_69b9c19c1021405984cc60dbbb1edceb147a6538b411d812ba6afabeed962cd5",
};

/// A parameter service every ROS 2 node offers (rclcpp's and rclpy's `ParameterService`),
/// on `/<node>/<suffix>`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParameterService {
    /// `describe_parameters`.
    Describe,
    /// `get_parameters` (what `ros2 param get` asks).
    Get,
    /// `get_parameter_types`.
    GetTypes,
    /// `list_parameters` (what `ros2 param list` asks).
    List,
    /// `set_parameters` (`ros2 param set`).
    Set,
    /// `set_parameters_atomically`.
    SetAtomically,
}

impl ParameterService {
    /// All six, in the order a real node declares them.
    pub const ALL: [ParameterService; 6] = [
        ParameterService::Describe,
        ParameterService::Get,
        ParameterService::GetTypes,
        ParameterService::List,
        ParameterService::Set,
        ParameterService::SetAtomically,
    ];

    /// The service's name under its node's (`get_parameters`).
    pub fn suffix(self) -> &'static str {
        match self {
            ParameterService::Describe => "describe_parameters",
            ParameterService::Get => "get_parameters",
            ParameterService::GetTypes => "get_parameter_types",
            ParameterService::List => "list_parameters",
            ParameterService::Set => "set_parameters",
            ParameterService::SetAtomically => "set_parameters_atomically",
        }
    }

    /// Its type (`rcl_interfaces/srv/GetParameters`).
    pub fn type_name(self) -> &'static str {
        match self {
            ParameterService::Describe => "rcl_interfaces/srv/DescribeParameters",
            ParameterService::Get => "rcl_interfaces/srv/GetParameters",
            ParameterService::GetTypes => "rcl_interfaces/srv/GetParameterTypes",
            ParameterService::List => "rcl_interfaces/srv/ListParameters",
            ParameterService::Set => "rcl_interfaces/srv/SetParameters",
            ParameterService::SetAtomically => "rcl_interfaces/srv/SetParametersAtomically",
        }
    }

    /// Its name, type and hash together.
    pub fn service_type(self) -> ServiceType {
        ServiceType {
            suffix: self.suffix(),
            type_name: self.type_name(),
            hash: self.hash(),
        }
    }

    /// Its type's RIHS01 hash.
    pub fn hash(self) -> &'static str {
        match self {
            ParameterService::Describe => {
                "RIHS01_845b484d71eb0673dae682f2e3ba3c4851a65a3dcfb97bddd82c5b57e91e4cff"
            }
            ParameterService::Get => {
                "RIHS01_bf9803d5c74cf989a5de3e0c2e99444599a627c7ff75f97b8c05b01003675cbc"
            }
            ParameterService::GetTypes => {
                "RIHS01_da199c878688b3e530bdfe3ca8f74cb9fa0c303101e980a9e8f260e25e1c80ca"
            }
            ParameterService::List => {
                "RIHS01_3e6062bfbb27bfb8730d4cef2558221f51a11646d78e7bb30a1e83afac3aad9d"
            }
            ParameterService::Set => {
                "RIHS01_56eed9a67e169f9cb6c1f987bc88f868c14a8fc9f743a263bc734c154015d7e0"
            }
            ParameterService::SetAtomically => {
                "RIHS01_0e192ef259c07fc3c07a13191d27002222e65e00ccec653ca05e856f79285fcd"
            }
        }
    }
}

/// The type info ([`TypeInfo`]) of the type named `ros_name` (`rcl_interfaces/msg/Log`) with
/// hash `rihs` (`RIHS01_…`, one of this module's).
///
/// # Panics
/// When `rihs` is not a RIHS01 string: this module's constants all are (a test reads each).
pub fn type_info(ros_name: &str, rihs: &str) -> TypeInfo {
    let hash = hiroz_schema::TypeHash::from_rihs_string(rihs).expect("a RIHS01 constant");
    let dds = hiroz_schema::dds_from_canonical(ros_name).unwrap_or_else(|| ros_name.to_string());
    TypeInfo::new(&dds, TypeHash::new(1, hash.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_hash_reads_as_rihs01_and_names_its_dds_type() {
        let mut all = vec![
            ("rcl_interfaces/msg/Log", LOG_HASH),
            ("rcl_interfaces/msg/ParameterEvent", PARAMETER_EVENT_HASH),
        ];
        all.extend(ParameterService::ALL.map(|s| (s.type_name(), s.hash())));
        all.push((GET_TYPE_DESCRIPTION.type_name, GET_TYPE_DESCRIPTION.hash));
        for (name, hash) in all {
            let info = type_info(name, hash);
            assert!(info.name.contains("::dds_::"), "{}", info.name);
            assert_eq!(
                hiroz_schema::TypeHash::from_rihs_string(hash)
                    .unwrap()
                    .to_rihs_string(),
                hash
            );
        }
        // The two messages' hashes, computed again from their descriptions (`echo`'s).
        for (name, hash) in [
            ("rcl_interfaces/msg/Log", LOG_HASH),
            ("rcl_interfaces/msg/ParameterEvent", PARAMETER_EVENT_HASH),
        ] {
            assert_eq!(
                super::super::echo::known()[name].hash.to_rihs_string(),
                hash
            );
        }
        assert_eq!(
            type_info(
                "rcl_interfaces/srv/GetParameters",
                ParameterService::Get.hash()
            )
            .name,
            "rcl_interfaces::srv::dds_::GetParameters_"
        );
    }
}
