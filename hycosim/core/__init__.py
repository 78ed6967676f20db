"""The shared core of the server and the nodes: the project file's models, guards, frames,
Zenoh keys and sessions, the inbox, logging, security, endpoints, run files and clocks."""
