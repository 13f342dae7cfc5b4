"""Imported only by the planner's forkserver (arm_process.WORKER_PRELOAD), never by the node: it
ignores SIGINT in the forkserver while that preloads. The forkserver saves the handlers it finds after
preloading and restores them in every child it forks, so each worker starts with SIGINT ignored — a
Ctrl-C aimed at the node's process group cannot interrupt a worker even before its main runs (it did,
between the fork and the worker's own signal call: a KeyboardInterrupt traceback at shutdown)."""
import signal

signal.signal(signal.SIGINT, signal.SIG_IGN)
