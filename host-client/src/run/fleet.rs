//! The VMs of a run (`arena_vm::fleet::VmFleet`) as the run sees its guests: the
//! pool's lifecycle (a snapshot restored before a task, a VM rebuilt when it
//! died) and the blame's watch (QEMU ended from outside). The observation's
//! stand-in screen (QEMU's screendump) is implemented beside its trait, in
//! `arena_agents::observation::observe`.

use arena_client::client::GuestClient;
use arena_results::VmStart;
use arena_vm::fleet::VmFleet;

use super::blame::GuestWatch;
use super::pool::GuestLifecycle;

#[async_trait::async_trait]
impl GuestLifecycle for VmFleet {
    async fn before_task(&self, guest: &GuestClient) -> Result<Option<VmStart>, String> {
        VmFleet::before_task(self, guest).await
    }

    async fn revive(&self, guest: &GuestClient) -> Result<(), String> {
        VmFleet::revive(self, guest).await
    }
}

#[async_trait::async_trait]
impl GuestWatch for VmFleet {
    async fn outside_failure(&self, guest: &str) -> Option<String> {
        VmFleet::outside_failure(self, guest).await
    }
}
