//! The QEMU image (`--features qemu`): the portable core against the simulated plant, on the
//! MCU, for `qemu-system-arm -machine netduinoplus2` (STM32F405, same family as the F407).
//!
//! QEMU 7.2 models this chip's core, NVIC, TIM2-5 (counting, update interrupt) and USARTs, but
//! not the RCC's ready flags, DMA, GPIO, encoder mode or input capture. So this image
//!
//! - runs on the reset clock (HSI, no PLL) and never waits on an RCC flag;
//! - lets [`VirtualRig`] supply what the board's timers and gyro would (encoder counts, index
//!   edges, data-ready instants, the L3G4200D's register answers through the real driver), in
//!   simulated time;
//! - paces that time with TIM3: one loop period per update interrupt, as on the board;
//! - speaks the protocol on USART1 (QEMU's first `-serial`): host bytes in by RXNE interrupt,
//!   frames out by polled writes, at most one period's worth of UART bytes per period.
//!
//! The panic and HardFault handlers make the motor safe as on the board, through the same
//! [`firmware::safe_state::make_motor_safe`]; this chip has no bridge, so the image's "pins"
//! report each write on USART1 instead (`safe state (panic): enable low, pwm 0`), for the boot
//! test to read (feature `qemu-panic-test` panics on purpose 100 ms in).
//!
//! | Priority | Source             | Work                                              |
//! |----------|--------------------|---------------------------------------------------|
//! | 2        | USART1 RXNE        | host byte into the receive queue                  |
//! | 1        | TIM3 update, 1 kHz | one loop period of the virtual rig; frames out    |

#[rtic::app(device = stm32f4xx_hal::pac, peripherals = true)]
mod app {
    use firmware::plant::Pose;
    use firmware::speed_loop::LOOP_HZ;
    use firmware::virtual_rig::{HostLink, VirtualRig, TICK_NS};
    use heapless::spsc::{Consumer, Producer, Queue};
    use stm32f4xx_hal::pac::{TIM3, USART1};

    /// TIM2-5 input clock in QEMU: the model fixes it at 48 MHz whatever the RCC holds
    /// (`hw/arm/stm32f405_soc.c`, timer "clock-frequency").
    const QEMU_TIMCLK_HZ: u32 = 48_000_000;

    /// USART1 kernel clock: APB2 = HSI = 16 MHz out of reset (RM0090 §7.3.3: RCC_CFGR resets to 0).
    const PCLK2_HZ: u32 = 16_000_000;

    /// 460 800 Bd: BRR = 35 is 457 kBd from 16 MHz (−0.8 %); 921 600 Bd is not reachable from
    /// HSI within 2 %. QEMU ignores the rate; a UART bridge on silicon would not.
    const BAUD: u32 = 460_800;

    /// USART_BRR for [`BAUD`] with 16× oversampling: the divider PCLK2 / baud, rounded
    /// (mantissa and 4-bit fraction read as one 12.4 number, RM0090 §30.3.4).
    const BRR: u16 = ((PCLK2_HZ + BAUD / 2) / BAUD) as u16;

    /// Bytes the UART moves per loop period (8N1: 10 bits a byte): 46, over twice the ≈ 18 B
    /// an 800 Hz sample stream needs (protocol/README.md, "Link budget").
    const UART_BYTES_PER_PERIOD: usize = (BAUD / 10 / LOOP_HZ) as usize;

    /// Host bytes between the receive interrupt and the loop (capacity N − 1): several command
    /// frames, and the loop drains it every millisecond.
    const RX_QUEUE: usize = 256;

    #[shared]
    struct Shared {}

    #[local]
    struct Local {
        tim3: TIM3,
        rig: VirtualRig,
        uart: Uart,
        rx_usart: USART1,
        rx: Producer<'static, u8>,
    }

    #[init(local = [rx_queue: Queue<u8, RX_QUEUE> = Queue::new()])]
    fn init(cx: init::Context) -> (Shared, Local) {
        let dp = cx.device;

        // Clocks stay as reset left them (HSI 16 MHz, no prescalers): only the gates change, and
        // nothing waits on a ready flag QEMU does not model.
        dp.RCC.apb1enr().modify(|_, w| w.tim3en().set_bit());
        dp.RCC.apb2enr().modify(|_, w| w.usart1en().set_bit());

        // USART1, 8N1, receive interrupt only: transmission is polled.
        let usart = dp.USART1;
        // SAFETY: every 16-bit value is a valid divider.
        usart.brr().write(|w| unsafe { w.bits(BRR) });
        usart.cr1().write(|w| {
            w.ue().set_bit();
            w.te().set_bit();
            w.re().set_bit();
            w.rxneie().set_bit()
        });

        // Test only: a panic in init, once USART1 can report it (the boot test then sees the
        // reset that follows, and the same report again).
        if cfg!(feature = "qemu-init-panic-test") {
            panic!("qemu-init-panic-test: a deliberate panic in init");
        }

        // Test only: a stack overflow (flip-link: it faults at the bottom of RAM).
        if cfg!(feature = "qemu-stack-overflow-test") {
            overflow(0);
        }

        // The prototype: TIM5 and the encoder counter start seconds before their 32-bit wrap,
        // so every stream crosses both.
        let mut rig = VirtualRig::prototype();
        rig.link_bytes_per_tick = UART_BYTES_PER_PERIOD;

        // Loop period: TIM3 update at LOOP_HZ from a 1 MHz count.
        let tim3 = dp.TIM3;
        tim3.psc().write(|w| w.psc().set((QEMU_TIMCLK_HZ / 1_000_000 - 1) as u16));
        tim3.arr().write(|w| w.arr().set((1_000_000 / LOOP_HZ - 1) as u16));
        tim3.egr().write(|w| w.ug().set_bit());
        tim3.sr().write(|w| w.uif().clear_bit());
        tim3.dier().write(|w| w.uie().set_bit());
        tim3.cr1().write(|w| w.cen().set_bit());

        let (rx, consumer) = cx.local.rx_queue.split();
        // SAFETY: the receive task only reads SR and DR (RDR); the transmit side only reads SR and
        // writes DR (TDR), a different register (RM0090 §30.6.2). No one writes the control
        // registers after this point.
        let rx_usart = unsafe { USART1::steal() };
        defmt::info!("qemu rig up");
        (Shared {}, Local { tim3, rig, uart: Uart { usart, rx: consumer }, rx_usart, rx })
    }

    /// Recursion without end, each frame 256 bytes of stack.
    #[allow(unconditional_recursion)]
    #[inline(never)]
    fn overflow(n: u32) -> u32 {
        let frame = core::hint::black_box([n; 64]);
        overflow(n + 1).wrapping_add(frame[usize::from(n as u8 & 63)])
    }

    #[idle]
    fn idle(_: idle::Context) -> ! {
        loop {
            cortex_m::asm::wfi();
        }
    }

    /// A host byte: into the queue for the next loop period.
    #[task(binds = USART1, priority = 2, local = [rx_usart, rx])]
    fn receive(cx: receive::Context) {
        let usart = cx.local.rx_usart;
        while usart.sr().read().rxne().bit_is_set() {
            let byte = usart.dr().read().dr().bits() as u8;
            // A full queue loses the byte; the rig counts the broken frame in `rx_errors`.
            let _ = cx.local.rx.enqueue(byte);
        }
    }

    /// One loop period of the simulated rig; the table is remounted in the pose each run's tag
    /// names (1, 2), as the pty virtual rig does.
    #[task(binds = TIM3, priority = 1, local = [tim3, rig, uart, mounted: Option<u8> = None])]
    fn period(cx: period::Context) {
        cx.local.tim3.sr().write(|w| w.uif().clear_bit());
        let rig = cx.local.rig;
        let end_ns = rig.now_ns() + TICK_NS;
        if cfg!(feature = "qemu-panic-test") && end_ns > 100_000_000 {
            panic!("qemu-panic-test: a deliberate panic");
        }
        rig.run_until(end_ns, cx.local.uart, |_| {});
        let tag = rig.rig.run_tag();
        if tag != *cx.local.mounted {
            if let Some(pose) = tag.and_then(Pose::from_run_tag) {
                rig.plant.pose = pose;
            }
            *cx.local.mounted = tag;
        }
    }

    /// USART1 as the virtual rig's host link.
    pub struct Uart {
        usart: USART1,
        rx: Consumer<'static, u8>,
    }

    impl HostLink for Uart {
        fn receive(&mut self, buf: &mut [u8]) -> usize {
            let mut n = 0;
            for slot in buf.iter_mut() {
                let Some(byte) = self.rx.dequeue() else { break };
                *slot = byte;
                n += 1;
            }
            n
        }

        fn send(&mut self, bytes: &[u8]) {
            for &byte in bytes {
                while self.usart.sr().read().txe().bit_is_clear() {}
                self.usart.dr().write(|w| w.dr().set(byte.into()));
            }
        }
    }
}

/// USART1, written by polling without owning it: the panic and HardFault handlers' only voice.
struct FaultUart;

impl core::fmt::Write for FaultUart {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        // SAFETY: called with interrupts disabled (panic) or from HardFault, when no task runs;
        // SR is only read and DR only written, as the transmit path of the app does.
        let usart = unsafe { &*stm32f4xx_hal::pac::USART1::ptr() };
        for byte in s.bytes() {
            while usart.sr().read().txe().bit_is_clear() {}
            usart.dr().write(|w| w.dr().set(byte.into()));
        }
        Ok(())
    }
}

/// The image's stand-in for the bridge enable: reports the level it is set to.
struct ReportedEnable;

impl embedded_hal::digital::ErrorType for ReportedEnable {
    type Error = core::convert::Infallible;
}

impl embedded_hal::digital::OutputPin for ReportedEnable {
    fn set_low(&mut self) -> Result<(), Self::Error> {
        let _ = core::fmt::Write::write_str(&mut FaultUart, "enable low, ");
        Ok(())
    }

    fn set_high(&mut self) -> Result<(), Self::Error> {
        let _ = core::fmt::Write::write_str(&mut FaultUart, "enable high, ");
        Ok(())
    }
}

/// The image's stand-in for the PWM compare: reports the duty it is set to.
struct ReportedPwm;

impl embedded_hal::pwm::ErrorType for ReportedPwm {
    type Error = core::convert::Infallible;
}

impl embedded_hal::pwm::SetDutyCycle for ReportedPwm {
    fn max_duty_cycle(&self) -> u16 {
        firmware::pwm::PWM_PERIOD_TICKS
    }

    fn set_duty_cycle(&mut self, duty: u16) -> Result<(), Self::Error> {
        let _ = core::fmt::write(&mut FaultUart, format_args!("pwm {duty}"));
        Ok(())
    }
}

/// The board's `force_motor_safe` for this image: the same action, on the reporting stand-ins,
/// as one line `safe state (<context>): enable low, pwm 0`.
pub fn force_motor_safe(context: &str) {
    use core::fmt::Write;
    let _ = write!(FaultUart, "\nsafe state ({context}): ");
    firmware::safe_state::make_motor_safe(&mut ReportedEnable, &mut ReportedPwm);
    let _ = FaultUart.write_str("\n");
}

/// The panic's message on USART1, `panic: <message>` (RTT has no reader under QEMU).
pub fn report_panic(info: &core::panic::PanicInfo) {
    use core::fmt::Write;
    let _ = writeln!(FaultUart, "panic: {}", info.message());
}
