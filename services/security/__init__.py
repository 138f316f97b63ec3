"""Zenoh security from configuration: credentials, TLS/mTLS, access control, the router."""
