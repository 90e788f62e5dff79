"""The backend-independent half of the executors (issue 22): what the wgpu and vk executors
share, written once. Backends import from here; passes never do."""
