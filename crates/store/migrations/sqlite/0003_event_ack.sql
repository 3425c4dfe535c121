-- Acknowledgements of events and alarms, from the dashboard (with the API token). Appended:
-- an event is acknowledged once, the first acknowledgement stays.
-- Mirrors ../postgres/0003_event_ack.sql.

CREATE TABLE event_acks (
    event_id INTEGER PRIMARY KEY NOT NULL REFERENCES events(id),
    at_ms    INTEGER NOT NULL,
    source   TEXT NOT NULL
);
