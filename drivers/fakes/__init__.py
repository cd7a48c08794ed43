"""Protocol-level fake devices for tests and bring-up rehearsal (see docs/drivers/fakes.md)."""
