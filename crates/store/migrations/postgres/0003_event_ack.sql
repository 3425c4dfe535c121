-- Acknowledgements of events and alarms, from the dashboard (with the API token). Appended:
-- an event is acknowledged once, the first acknowledgement stays.
-- Mirrors ../sqlite/0003_event_ack.sql.

CREATE TABLE event_acks (
    event_id BIGINT PRIMARY KEY REFERENCES events(id),
    at_ms    BIGINT NOT NULL,
    source   TEXT NOT NULL
);
