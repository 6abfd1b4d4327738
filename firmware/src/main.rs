//! The rig firmware: an rtic 2 app on the STM32F407 (STM32F4DISCOVERY).
//!
//! Interrupts only move data between registers and the portable core ([`firmware::rig::Rig`]):
//!
//! | Priority | Source            | Work                                                      |
//! |----------|-------------------|-----------------------------------------------------------|
//! | 3        | TIM5 capture      | data-ready: captured time + count, SPI burst read; index  |
//! | 2        | TIM3 update, 1 kHz| speed loop, supervision, periodic frames, watchdog feed (while USB runs) |
//! | 1        | OTG_FS            | USB CDC-ACM: host bytes in, queued frames out             |
//!
//! Sampling preempts everything, so a slow host or a long USB transfer never delays a read.
//!
//! With the `qemu` feature the image is instead [`qemu`]'s app: the same core against the
//! simulated plant, for QEMU's `netduinoplus2`.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(all(target_os = "none", not(feature = "qemu")))]
mod board;
#[cfg(all(target_os = "none", not(feature = "qemu")))]
mod capture;
#[cfg(all(target_os = "none", feature = "qemu"))]
mod qemu;

#[cfg(all(target_os = "none", not(feature = "qemu")))]
use stm32f4xx_hal::pac;

#[cfg(target_os = "none")]
use defmt_rtt as _;

/// A panic: the motor is made safe before anything else (printing the message over RTT takes
/// time, a debug probe may not even be attached), then the message, then a HardFault (`udf`),
/// which makes the motor safe again and which probe-rs reports; the watchdog resets the MCU.
/// The QEMU image has no bridge: its stand-ins report the same action on USART1.
#[cfg(target_os = "none")]
#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    cortex_m::interrupt::disable();
    #[cfg(not(feature = "qemu"))]
    board::force_motor_safe();
    #[cfg(feature = "qemu")]
    {
        qemu::force_motor_safe("panic");
        qemu::report_panic(info);
    }
    defmt::error!("panic: {}", defmt::Display2Format(info));
    // SAFETY: SHCSR (0xE000_ED24) is the System Handler Control and State Register; clearing
    // USGFAULTENA (bit 18) makes `udf` a HardFault rather than a UsageFault (as panic-probe does).
    unsafe {
        let shcsr = 0xE000_ED24 as *mut u32;
        core::ptr::write_volatile(shcsr, core::ptr::read_volatile(shcsr) & !(1 << 18));
    }
    cortex_m::asm::udf()
}

/// The firmware only runs on the MCU; on the host, `cargo build --workspace` builds this stub
/// and the logic is exercised through the library's tests and the virtual rig.
#[cfg(not(target_os = "none"))]
fn main() {}

/// HardFault's entry, on a fresh stack: the stack pointer is set back to the top of the stack
/// region (`_stack_start`) before any code pushes, then [`hard_fault`] runs. A stack overflow
/// (flip-link puts the stack at the bottom of RAM, so an overflow faults at 0x2000_0000) enters
/// HardFault with the stack pointer below RAM; a handler that pushed there would fault again
/// and lock the core up (measured in QEMU: "Lockup: can't escalate 3 to HardFault"), with the
/// bridge as it was until the watchdog's reset. HardFault never returns: the old stack is not
/// needed.
#[cfg(target_os = "none")]
#[unsafe(naked)]
#[unsafe(no_mangle)]
unsafe extern "C" fn HardFault() -> ! {
    core::arch::naked_asm!(
        "ldr r0, =_stack_start",
        "msr msp, r0",
        "b {handler}",
        handler = sym hard_fault,
    )
}

/// A fault (and every panic, which ends here): the motor is made safe
/// before anything else, then the watchdog resets the MCU. Without this the bridge kept its
/// last duty until the reset (34-94 ms: the LSI is 17-47 kHz).
#[cfg(all(target_os = "none", not(feature = "qemu")))]
extern "C" fn hard_fault() -> ! {
    board::force_motor_safe();
    loop {
        cortex_m::asm::nop();
    }
}

/// The QEMU image's HardFault: the same safe action, reported on USART1, then a system reset:
/// QEMU 7.2 models no IWDG, so the reset the board's watchdog would make 34-94 ms later is
/// requested here (SYSRESETREQ, which QEMU does model), and the boot test sees the image start
/// again after a panic in `init` or a stack overflow.
#[cfg(all(target_os = "none", feature = "qemu"))]
extern "C" fn hard_fault() -> ! {
    qemu::force_motor_safe("HardFault");
    cortex_m::peripheral::SCB::sys_reset()
}

#[cfg(all(target_os = "none", not(feature = "qemu")))]
#[rtic::app(device = stm32f4xx_hal::pac, peripherals = true)]
mod app {
    use crate::board::{self, Motor, GYRO_SPI_HZ};
    use crate::capture::{Captures, Counters};
    use embedded_hal_bus::spi::ExclusiveDevice;
    use firmware::l3g4200d::L3g4200d;
    use firmware::rig::{GyroControl, Rig};
    use firmware::speed_loop::LOOP_HZ;
    use stm32f4xx_hal::{
        gpio::{Output, PinState, PE7},
        otg_fs::{UsbBus, UsbBusType, USB},
        pac::{self, Interrupt, SPI1, TIM3},
        prelude::*,
        rcc::Config,
        spi::Spi,
        watchdog::IndependentWatchdog,
    };
    use usb_device::{bus::UsbBusAllocator, prelude::*};
    use usbd_serial::SerialPort;

    type GyroSpi = ExclusiveDevice<Spi<SPI1>, PE7<Output>, embedded_hal_bus::spi::NoDelay>;

    /// USB OUT endpoint buffer for the OTG core: control (64 B) + CDC data (64 B), with room.
    const EP_MEMORY_WORDS: usize = 320;

    /// IWDG timeout: 50 loop periods. A hung loop leaves the bridge disabled (EN pull-down)
    /// after the reset.
    const WATCHDOG_MS: u32 = 50;

    #[shared]
    struct Shared {
        rig: Rig,
        gyro: L3g4200d<GyroSpi>,
    }

    #[local]
    struct Local {
        captures: Captures,
        counters: Counters,
        /// The same read-only counters, for the USB task to time host frames.
        clock: Counters,
        tim3: TIM3,
        motor: Motor,
        watchdog: IndependentWatchdog,
        usb_dev: UsbDevice<'static, UsbBusType>,
        serial: SerialPort<'static, UsbBusType>,
    }

    #[init(local = [
        ep_memory: [u32; EP_MEMORY_WORDS] = [0; EP_MEMORY_WORDS],
        usb_bus: Option<UsbBusAllocator<UsbBusType>> = None,
    ])]
    fn init(cx: init::Context) -> (Shared, Local) {
        let dp = cx.device;

        // Why did we reset? Read before anything clears it.
        let watchdog_reset = dp.RCC.csr().read().wdgrstf().bit_is_set();
        dp.RCC.csr().modify(|_, w| w.rmvf().set_bit());

        // Debug halt (breakpoint, probe-rs): the watchdog pauses instead of resetting the MCU,
        // and TIM1 stops with its outputs disabled as if MOE = 0 (RM0090, TIM1/TIM8 "Debug mode"), so a
        // halted core does not leave the motor driven.
        dp.DBGMCU.apb1_fz().modify(|_, w| w.dbg_iwdg_stop().set_bit());
        dp.DBGMCU.apb2_fz().modify(|_, w| w.dbg_tim1_stop().set_bit());

        // The watchdog before anything that can panic or hang (clock start-up, the gyro probe,
        // USB): a panic in init ends in the HardFault loop with the motor safe, and the watchdog
        // then resets the MCU instead of leaving the rig dead until a power cycle. The bridge
        // is off until the pins are set up below (EN pulled down out of reset). Everything up
        // to the first feed (the first control tick) takes a few ms, well inside the 34 ms the
        // fastest LSI (47 kHz) leaves of WATCHDOG_MS.
        let mut watchdog = IndependentWatchdog::new(dp.IWDG);
        watchdog.start(WATCHDOG_MS.millis());

        // 8 MHz HSE crystal → 168 MHz core, 48 MHz for USB; APB1 timers 84 MHz, APB2 168 MHz.
        let mut rcc = dp.RCC.freeze(Config::hse(8.MHz()).sysclk(168.MHz()).require_pll48clk());
        let timclk1 = rcc.clocks.timclk1().raw();

        let gpioa = dp.GPIOA.split(&mut rcc);
        let gpiob = dp.GPIOB.split(&mut rcc);
        let gpioe = dp.GPIOE.split(&mut rcc);

        // Motor: off before anything else can run.
        let en = gpioe.pe11.into_push_pull_output_in_state(PinState::Low);
        let dir = gpioe.pe10.into_push_pull_output_in_state(PinState::Low);
        let (_, (pwm, ..)) = dp.TIM1.pwm_hz(20.kHz(), &mut rcc);
        let mut pwm = pwm.with(gpioe.pe9);
        pwm.set_duty(0);
        pwm.enable();
        defmt::assert_eq!(pwm.get_max_duty(), firmware::pwm::PWM_PERIOD_TICKS);
        let mut motor = Motor { pwm, dir, en };
        motor.apply(firmware::pwm::MotorCommand::OFF);

        // Encoder, index and data-ready inputs.
        gpioa.pa15.into_alternate::<1>(); // TIM2_CH1, encoder A
        gpiob.pb3.into_alternate::<1>(); // TIM2_CH2, encoder B
        gpiob.pb10.into_alternate::<1>(); // TIM2_CH3, index → count
        gpiob.pb11.into_alternate::<1>(); // TIM2_CH4, DRDY → count
        gpioa.pa2.into_alternate::<2>(); // TIM5_CH3, index → time
        gpioa.pa3.into_alternate::<2>(); // TIM5_CH4, DRDY → time
                                         // SAFETY: enabling peripheral clocks through the RCC the HAL has configured.
        unsafe {
            let rcc_regs = &*pac::RCC::ptr();
            rcc_regs.apb1enr().modify(|_, w| {
                w.tim2en().set_bit();
                w.tim3en().set_bit();
                w.tim5en().set_bit()
            });
        }
        let (captures, counters) = Captures::new(dp.TIM2, dp.TIM5, timclk1);

        // Gyro on SPI1, mode 3; the on-board accelerometer on the same bus stays deselected.
        let _accel_cs = gpioe.pe3.into_push_pull_output_in_state(PinState::High);
        let cs = gpioe.pe7.into_push_pull_output_in_state(PinState::High);
        let bus = dp.SPI1.spi(
            (Some(gpioa.pa5), Some(gpioa.pa6), Some(gpioa.pa7)),
            embedded_hal::spi::MODE_3,
            GYRO_SPI_HZ.Hz(),
            &mut rcc,
        );
        let mut gyro = L3g4200d::new(ExclusiveDevice::new_no_delay(bus, cs).unwrap());
        let config = protocol::GyroConfig::DEFAULT;
        let probe = gyro.apply(config);
        if probe.is_err() {
            defmt::error!("gyro probe failed; reported to the host");
        }

        // Control loop tick: TIM3 update at LOOP_HZ.
        let tim3 = dp.TIM3;
        tim3.psc().write(|w| w.psc().set((timclk1 / 1_000_000 - 1) as u16));
        tim3.arr().write(|w| w.arr().set((1_000_000 / LOOP_HZ - 1) as u16));
        tim3.egr().write(|w| w.ug().set_bit());
        tim3.sr().write(|w| w.uif().clear_bit());
        tim3.dier().write(|w| w.uie().set_bit());
        tim3.cr1().write(|w| w.cen().set_bit());

        // USB CDC-ACM.
        let usb =
            USB::new((dp.OTG_FS_GLOBAL, dp.OTG_FS_DEVICE, dp.OTG_FS_PWRCLK), (gpioa.pa11, gpioa.pa12), &rcc.clocks);
        let usb_bus: &'static _ = cx.local.usb_bus.insert(UsbBus::new(usb, cx.local.ep_memory));
        let serial = SerialPort::new(usb_bus);
        let usb_dev = UsbDeviceBuilder::new(usb_bus, UsbVidPid(0x16c0, 0x27dd))
            .device_class(usbd_serial::USB_CLASS_CDC)
            .strings(&[StringDescriptors::default()
                .manufacturer("gyro exciter")
                .product("two-table exciter rig")
                .serial_number("0001")])
            .unwrap()
            .build();

        let mut rig = Rig::new(config);
        rig.power_up(counters.now_us(), probe, watchdog_reset);

        watchdog.feed();
        defmt::info!("rig up; watchdog reset: {}", watchdog_reset);

        (Shared { rig, gyro }, Local { captures, counters, clock: counters, tim3, motor, watchdog, usb_dev, serial })
    }

    #[idle]
    fn idle(_: idle::Context) -> ! {
        loop {
            cortex_m::asm::wfi();
        }
    }

    /// Data-ready and index edges, captured by TIM2/TIM5.
    #[task(binds = TIM5, priority = 3, shared = [rig, gyro], local = [captures])]
    fn edges(cx: edges::Context) {
        let edges::SharedResources { mut rig, mut gyro, .. } = cx.shared;
        let captures = cx.local.captures;
        if let Some(c) = captures.data_ready() {
            let read = gyro.lock(|g| g.read());
            // A read that trips the run cuts the bridge here, not up to 1 ms later at the next
            // control tick (which applies the same OFF).
            if rig.lock(|r| r.data_ready(c.t_us, c.encoder, read)).is_some() {
                board::cut_drive();
            }
        }
        if let Some(c) = captures.index() {
            let level = board::index_level();
            rig.lock(|r| r.index_edge(c.t_us, c.encoder, level, c.overcaptured));
        }
        rtic::pend(Interrupt::OTG_FS);
    }

    /// The speed loop period.
    #[task(binds = TIM3, priority = 2, shared = [rig, gyro], local = [tim3, counters, motor, watchdog])]
    fn control(mut cx: control::Context) {
        cx.local.tim3.sr().write(|w| w.uif().clear_bit());
        let t_us = cx.local.counters.now_us();
        let encoder = cx.local.counters.encoder();
        let drdy_high = board::drdy_level();
        let motor = cx.local.motor;
        // Applied under the lock: a data-ready trip cannot fall between computing the command
        // and applying it, and be undone by a command computed before it.
        let (release, feed) = cx.shared.rig.lock(|r| {
            motor.apply(r.control_tick(t_us, encoder));
            (r.needs_drdy_release(drdy_high), r.watchdog_may_feed(t_us))
        });
        if release {
            let _ = cx.shared.gyro.lock(|g| g.read());
        }
        // Only while the USB task still runs: a hung one ends in a watchdog reset.
        if feed {
            cx.local.watchdog.feed();
        }
        rtic::pend(Interrupt::OTG_FS);
    }

    /// USB: host commands in, frames out. Bytes the endpoint did not take wait in `pending`.
    #[task(binds = OTG_FS, priority = 1, shared = [rig, gyro],
           local = [usb_dev, serial, clock, pending: [u8; 64] = [0; 64], sent: usize = 0, len: usize = 0])]
    fn usb(cx: usb::Context) {
        let usb::SharedResources { mut rig, mut gyro, .. } = cx.shared;
        let usb::LocalResources { usb_dev, serial, clock, pending, sent, len, .. } = cx.local;
        let now_us = clock.now_us();
        rig.lock(|r| r.usb_task_ran(now_us));
        if usb_dev.poll(&mut [serial]) {
            let mut rx = [0u8; 64];
            if let Ok(n) = serial.read(&mut rx) {
                let t_us = clock.now_us();
                (&mut rig, &mut gyro).lock(|r, g| r.receive(t_us, &rx[..n], g));
            }
        }
        loop {
            if *sent == *len {
                *len = rig.lock(|r| r.link().tx().pop_into(pending));
                *sent = 0;
                if *len == 0 {
                    break;
                }
            }
            match serial.write(&pending[*sent..*len]) {
                Ok(n) if n > 0 => *sent += n,
                _ => break,
            }
        }
    }
}
