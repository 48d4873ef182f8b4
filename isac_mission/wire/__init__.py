"""The neutral wire layer: bus payloads as typed messages, their envelope and key expressions,
strict JSON, and the JSON Schema of every message (docs/bus.md). Imports neither the service nor
`sim`, and no network library."""
