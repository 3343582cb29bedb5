//! An iceoryx2 service type whose events wake through a semaphore in shared memory (a futex
//! underneath) instead of a Unix datagram (issue 46).
//!
//! iceoryx2 0.10's `ipc::Service` notifies through `UnixDatagramShmCountingBitSet`: every
//! notification is a datagram sent to each listener's socket beside a bit set in shared
//! memory, and a woken listener reads the socket. The same crate ships
//! `SemaphoreShmCountingBitSet`: the bit set, and a process-shared semaphore each listener
//! sleeps on, so a notification is an atomic add and, when the listener sleeps, one futex
//! wake. What it gives up is a file descriptor: a semaphore listener cannot join a `ppoll`
//! with other descriptors (a device, a server's wake), so a process sleeps on one such
//! listener alone, which every publisher it reads notifies (`bus::Doorbell`).
//!
//! [`SemaphoreIpc`] is `ipc::Service` with that one associated type changed; every other
//! resource (the static and dynamic storage, the shared memory, the connections, the
//! monitoring) is the same, under the same configuration, prefix and root path.

use core::fmt::Debug;

use iceoryx2_bb_elementary_traits::testing::abandonable::Abandonable;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use iceoryx2_cal::shm_allocator::bump_allocator::BumpAllocator;
use iceoryx2_cal::shm_allocator::pool_allocator::PoolAllocator;
use iceoryx2_cal::*;

/// `ipc::Service` with semaphore events (see the module's doc).
#[derive(Debug, Clone)]
pub struct SemaphoreIpc {}

impl iceoryx2::service::Service for SemaphoreIpc {
    type StaticStorage = static_storage::recommended::Ipc;
    type ConfigSerializer = serialize::recommended::Recommended;
    type PersistentDynamicStorage<T: Debug + Send + Sync + ZeroCopySend + 'static> =
        dynamic_storage::recommended::PersistentIpc<T>;
    type Bag = bag::recommended::Recommended;
    type DynamicStorage<T: Debug + Send + Sync + ZeroCopySend + 'static> =
        dynamic_storage::recommended::Ipc<T>;
    type ServiceNameHasher = hash::recommended::Recommended;
    type SharedMemory = shared_memory::recommended::Ipc<PoolAllocator>;
    type ResizableSharedMemory = resizable_shared_memory::recommended::Ipc<PoolAllocator>;
    type Connection = zero_copy_connection::recommended::Ipc;
    /// The one change from `ipc::Service`.
    type Event = event::SemaphoreShmCountingBitSet;
    type Monitoring = monitoring::recommended::Ipc;
    type Reactor = reactor::recommended::Ipc;
    type ArcThreadSafetyPolicy<T: Send + Debug + Abandonable> =
        arc_sync_policy::single_threaded::SingleThreaded<T>;
    type BlackboardMgmt<KeyType: Send + Sync + Debug + ZeroCopySend + 'static> =
        dynamic_storage::recommended::Ipc<KeyType>;
    type BlackboardPayload = shared_memory::recommended::Ipc<BumpAllocator>;
    type UniqueId = iceoryx2::unique_id_generator::unique_system_id::UniqueSystemId;
}

impl iceoryx2::service::internal::ServiceInternal<SemaphoreIpc> for SemaphoreIpc {}
