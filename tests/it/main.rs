//! The integration tests, as one test binary: each former `tests/*.rs` file is a module,
//! and the support modules are compiled once. The three-instance takeover and the crash
//! points run here too: they drive `camloop` processes of their own and bound times in
//! seconds, which hold with the other tests beside them as they do with both cores kept busy
//! from outside; running beside the rest, their waiting overlaps its work. Only the browser
//! tests are a binary of their own (`tests/browser/`).

#[path = "../cli_support/mod.rs"]
mod cli_support;
#[path = "../cluster_support/mod.rs"]
mod cluster_support;
#[path = "../common/cycloid_cam.rs"]
mod cycloid_cam;
#[path = "../fixture_support/mod.rs"]
mod fixture_support;
#[path = "../gauge_drop_support/mod.rs"]
mod gauge_drop_support;
#[path = "../history_support/mod.rs"]
mod history_support;
#[path = "../machine_support/mod.rs"]
mod machine_support;
#[path = "../mqtt_support/mod.rs"]
mod mqtt_support;
#[path = "../opcua_support/mod.rs"]
mod opcua_support;
#[path = "../common/overview_reference.rs"]
mod overview_reference;
#[path = "../process_support/mod.rs"]
mod process_support;
#[path = "../rs274_support/mod.rs"]
mod rs274_support;
#[path = "../service_support/mod.rs"]
mod service_support;
#[path = "../share_support/mod.rs"]
mod share_support;
#[path = "../sim_support/mod.rs"]
mod sim_support;
#[path = "../sinumerik_support/mod.rs"]
mod sinumerik_support;
#[path = "../store_support/mod.rs"]
mod store_support;
#[path = "../support/mod.rs"]
mod support;

mod access_cli;
mod access_lockout;
mod access_matrix;
mod access_signin;
mod analysis_accuracy;
mod analysis_assembly;
mod analysis_fixture;
mod analysis_harmonics;
mod analysis_lobe;
mod analysis_pin;
mod cli_analyze;
mod cli_capability;
mod cli_compensate;
mod cli_generate;
mod cli_history;
mod cli_run;
mod cli_speed_plan;
mod cli_table;
mod cluster_takeover;
mod config_check;
mod control_coupling;
mod crank_service;
mod dashboard_http;
mod dashboard_overview;
mod docs;
mod docs_commands;
mod gauge_can;
mod gauge_can_live;
mod gauge_drop_complete;
mod gauge_drop_entries;
mod gauge_drop_folder;
mod gauge_drop_memory;
mod gauge_encode;
mod gauge_file;
mod gauge_proptest;
mod gauge_serial;
mod gauge_serial_codec;
mod generate_contour;
mod generate_contour_file;
mod generate_contour_rparams;
mod generate_contour_sources;
mod generate_planing;
mod generate_planing_table;
mod generate_turnmill;
mod geometry_accuracy;
mod geometry_oracle;
mod geometry_props;
mod http_harden;
mod http_tls;
mod in_process;
mod in_process_figures;
mod in_process_plan_figures;
mod in_process_resume;
mod in_process_service;
mod in_process_shafts;
mod in_process_timeout;
mod invariants;
mod loop_plateau;
mod loop_sim;
mod loop_speed_plan;
mod machine_plan_memory;
mod machine_write_errors;
mod mqtt_broker;
mod mqtt_secure;
mod opcua_asyncua;
mod opcua_browse;
mod opcua_feed;
mod opcua_limits;
mod opcua_node;
mod opcua_overflow;
mod opcua_restart;
mod opcua_watch;
mod opcua_write_audit;
mod plant_event_order;
mod program_retarget;
mod program_settings;
mod program_svg;
mod program_tables;
mod recipe;
mod run_rules;
mod service_crash_points;
mod service_database_health;
mod service_disk_full;
mod service_faults;
mod service_gauges;
mod service_http;
mod service_identity;
mod service_kill;
mod service_plant;
mod service_run;
mod shaft_routing;
mod shaft_service;
mod shaft_speed_plan;
mod share_faults;
mod share_fence;
mod share_kill;
mod share_manifest_bound;
mod share_push;
mod sim_envelope;
mod sim_gauge;
mod sim_machine;
mod sim_wheel;
mod store_batch;
mod store_chains;
mod store_errors;
mod store_masters;
mod store_migrate;
mod store_schema;
mod store_story;
mod store_writes;
mod var_private;
